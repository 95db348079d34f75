"""The cone detector: a model file in, boxes out.

* :mod:`.detector`: :class:`Detector` (load a model file for a backend, run it on a band or an image) and
  :func:`detect_one` (one full image as ``detect`` runs it);
* :mod:`.backends`: ONNX Runtime's runner and sessions, ``auto``'s choice (:func:`resolve_backend`); the eager torch
  and TorchScript runners: :mod:`.torch_backend` (torch, imported on use);
* :mod:`.onnx_cache`: the ONNX graphs of the ``.pt`` models, cached, so a warm start on ONNX Runtime imports no torch;
* :mod:`.preprocess`: letterbox and the network input blob;
* :mod:`.model_files`: the default model's path, sidecars and embedded class names of exported models;
* :mod:`.export`: export to TorchScript / ONNX with the description embedded, and the check against eager;
* :mod:`.quantize`: static int8 quantisation of an exported ONNX model.

The names below are the face of the former module ``cone_perception.detector``:
``from cone_perception.detector import Detector, default_model_path`` keeps working.
"""

from ..params import DEFAULT_BACKEND, DEFAULT_CONF, DEFAULT_IOU, DEFAULT_MAX_DET, RUNTIME_THREADS
from .backends import BACKEND_CHOICES, BACKENDS, resolve_backend
from .detector import Detector, detect_one
from .model_files import DEFAULT_MODEL_NAME, default_model_path, find_sidecar, read_sidecar, sidecar_path, write_sidecar
from .preprocess import PAD_VALUE, Letterbox, band_input_size, letterbox, preprocess, round_up32

__all__ = [
    "BACKEND_CHOICES", "BACKENDS", "DEFAULT_BACKEND", "DEFAULT_CONF", "DEFAULT_IOU", "DEFAULT_MAX_DET",
    "DEFAULT_MODEL_NAME", "PAD_VALUE", "RUNTIME_THREADS", "Detector", "Letterbox", "band_input_size",
    "default_model_path", "detect_one", "find_sidecar", "letterbox", "preprocess", "read_sidecar",
    "resolve_backend", "round_up32", "sidecar_path", "write_sidecar",
]
