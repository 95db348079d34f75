"""The YOLO-style cone detector: blocks, backbone, neck, head, loss, assignment, decode.

Read in this order: :mod:`.config` (named sizes), :mod:`.blocks`, :mod:`.backbone`,
:mod:`.neck`, :mod:`.head`, :mod:`.yolo` (composes them); for training
:mod:`.assign` and :mod:`.loss`; for inference :mod:`.decode`.
"""

from .config import MODEL_SIZES, PRETRAINED_BACKBONES, ModelConfig, is_model_name, model_config, model_names
from .yolo import ConeYOLO

__all__ = ["MODEL_SIZES", "PRETRAINED_BACKBONES", "ModelConfig", "model_config", "model_names", "is_model_name", "ConeYOLO"]
