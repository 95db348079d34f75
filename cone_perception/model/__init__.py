"""The YOLO-style cone detector: blocks, backbone, neck, head, loss, assignment, decode.

Read in this order: :mod:`.config` (named sizes), :mod:`.blocks`, :mod:`.backbone`,
:mod:`.neck`, :mod:`.head`, :mod:`.yolo` (composes them); for training
:mod:`.assign` and :mod:`.loss`; for inference :mod:`.decode` (the boxes after the network, numpy:
:mod:`.postprocess`).

The network (:class:`ConeYOLO`) is torch's and imported on first use, so :mod:`.config` and
:mod:`.postprocess` load without torch (a node on ONNX Runtime with the ONNX cache warm, issue 43).
"""

from .config import MODEL_SIZES, PRETRAINED_BACKBONES, ModelConfig, is_model_name, model_config, model_names

__all__ = ["MODEL_SIZES", "PRETRAINED_BACKBONES", "ModelConfig", "model_config", "model_names", "is_model_name", "ConeYOLO"]


def __getattr__(name: str):
    if name == "ConeYOLO":  # torch: only where the network itself is built
        from .yolo import ConeYOLO

        return ConeYOLO
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
