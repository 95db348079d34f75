"""The YOLO-style cone detector: blocks, backbone, neck, head, loss, assignment, decode.

Read in this order: :mod:`.config` (named sizes), :mod:`.blocks`, :mod:`.backbone`,
:mod:`.neck`, :mod:`.head`, :mod:`.yolo` (composes them); for training
:mod:`.assign` and :mod:`.loss`; for inference :mod:`.decode`.
"""

from .config import MODEL_SIZES, ModelConfig, model_config
from .yolo import ConeYOLO

__all__ = ["MODEL_SIZES", "ModelConfig", "model_config", "ConeYOLO"]
