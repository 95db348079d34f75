"""Training of the cone detector: datasets (YOLO txt layout), augmentation, the loop.

Entry point: ``cone-perception train`` (:mod:`cone_perception.commands.train`),
which calls :func:`.trainer.train` with a :class:`.trainer.TrainConfig`.
"""
