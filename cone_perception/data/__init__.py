"""Files and recordings the tools share: rosbag2 I/O (:mod:`.bagio`) and a bag's topics (:mod:`.bags`),
image sources (:mod:`.sources`), the dataset format (:mod:`.datasets`, :mod:`.yolo_yaml`), prediction
files (:mod:`.predictions`), FSOCO conversion (:mod:`.convert`), output files (:mod:`.outfiles`),
crafted inputs for the fuzzer (:mod:`.hostile`), the docs generated from the parameter schema (:mod:`.paramdocs`). Imports no torch; the runtime imports nothing from here.
"""
