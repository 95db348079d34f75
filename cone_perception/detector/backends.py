"""The backends a :class:`~cone_perception.detector.Detector` runs on: eager torch, TorchScript, ONNX Runtime.
Each runner takes (1, 3, H, W) float32 RGB 0..1 and returns (4 + nc, N) float32 numpy. This module imports no
torch (the ONNX Runtime path of the nodes starts without it, issue 43); the torch runners live in
:mod:`.torch_backend`."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..resources import user_cache_dir

BACKENDS = ("torch", "torchscript", "onnx")
#: The ONNX opset the package exports to (``export``, the ONNX cache).
ONNX_OPSET = 17
#: What ``backend`` may be: a backend, or ``auto`` (:func:`resolve_backend`), the default everywhere.
BACKEND_CHOICES = ("auto", *BACKENDS)


def resolve_backend(backend: str, path: str | Path | None = None, device: str = "cpu", bf16: bool = False,
                    fp16: bool = False) -> str:
    """The backend ``backend`` stands for: itself, or for ``auto`` the fastest one the model can run
    with here: an exported file's own (``.onnx`` -> onnx, ``.torchscript`` / ``.ts`` -> torchscript);
    for a checkpoint (``path`` ``.pt``, or None = in memory) ONNX Runtime on the CPU when it and
    ``onnx`` are installed (a faster forward than eager torch's, the same boxes), else eager torch
    (a GPU, ``bf16`` / ``fp16``). The loaded detector's :attr:`Detector.backend` says which."""
    if backend != "auto":
        return backend
    suffix = Path(path).suffix.lower() if path is not None else ".pt"
    if suffix == ".onnx":
        return "onnx"
    if suffix in (".torchscript", ".ts"):
        return "torchscript"
    if device != "cpu" or bf16 or fp16:
        return "torch"
    # ONNX Runtime runs it; torch's exporter needs the onnx package to build it (looked up, not imported: a start
    # from the ONNX cache imports neither onnx nor torch)
    return "onnx" if installed("onnx") and installed("onnxruntime") else "torch"


def installed(module: str) -> bool:
    """Whether ``module`` can be imported here (found on the path; not imported)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


class OrtRunner:
    """An ONNX Runtime session: (1, 3, H, W) float32 RGB 0..1 -> (4 + nc, N) float32 numpy (fp16 inputs cast).
    ``fp16``: an fp16 graph, or TensorRT building its engine in fp16 (:func:`ort_session` with ``fp16``);
    ``provider``: the execution provider that runs it first (``TensorrtExecutionProvider``, ``CUDAExecutionProvider``
    or ``CPUExecutionProvider``)."""

    def __init__(self, session):
        self.session = session
        self.input_name = session.get_inputs()[0].name
        self.provider = session.get_providers()[0]
        trt = session.get_provider_options().get(TRT_PROVIDER, {}) if self.provider == TRT_PROVIDER else {}
        self.half_input = session.get_inputs()[0].type == "tensor(float16)"  # the graph takes fp16: cast to it
        self.fp16 = self.half_input or str(trt.get("trt_fp16_enable")) in ("1", "True")

    def __call__(self, blob: np.ndarray) -> np.ndarray:
        x = blob.astype(np.float16) if self.half_input else blob
        return np.asarray(self.session.run(None, {self.input_name: x})[0][0], dtype=np.float32)


def ort_spinning(threads: int | None) -> bool:
    """Whether ONNX Runtime's intra-op threads may spin after their work (``session.intra_op.allow_spinning``):
    only in a one-thread session, which has no pool. A pool (``threads >= 2``, or 0 / None: one thread a core)
    whose threads spin keeps a core busy between forwards and loses a scheduler tick at each synchronisation
    point whenever other work runs (docs/benchmarks.md, "Band and far strip at once on two threads" and
    "Band rows and ONNX Runtime spinning")."""
    return threads == 1


TRT_PROVIDER, CUDA_PROVIDER, CPU_PROVIDER = "TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider"


def trt_cache_dir() -> Path:
    """Where ONNX Runtime's TensorRT provider keeps the engines it builds (:func:`user_cache_dir` /
    ``tensorrt``): the first start with a model and input size builds one (minutes on a
    Jetson), later starts load it. An engine holds for one GPU, TensorRT version and input size; ONNX Runtime
    keys its files by the model and builds anew where they do not match."""
    return user_cache_dir() / "tensorrt"


def ort_providers(device: str, fp16: bool, available: list[str], source: str) -> list:
    """ONNX Runtime's providers for ``device``: the CPU's alone for ``cpu``; for ``cuda`` / ``cuda:N`` TensorRT
    first where this ONNX Runtime has it (its engine in fp16 with ``fp16``, cached in :func:`trt_cache_dir`), then
    CUDA, each on device N, the CPU last (for what they cannot run). A :class:`ConfigError` naming ``device`` when
    it asks for a GPU this ONNX Runtime has no provider for (the PyPI ``onnxruntime`` is CPU-only), and naming
    ``fp16`` when fp16 is asked without TensorRT (the CUDA provider runs the graph in fp32)."""
    if not device.startswith("cuda"):
        return [CPU_PROVIDER]
    index = device.partition(":")[2] or "0"
    if not index.isdigit():
        raise ConfigError(source, "device", f"must be cpu, cuda or cuda:N, got {device!r}")
    gpu = [p for p in (TRT_PROVIDER, CUDA_PROVIDER) if p in available]
    if not gpu:
        raise ConfigError(source, "device", f"{device!r} with backend 'onnx' needs ONNX Runtime with a GPU provider "
                                            f"(onnxruntime-gpu, or NVIDIA's build for the Jetson); this one has "
                                            f"{', '.join(available) or 'none'}")
    if fp16 and TRT_PROVIDER not in gpu:
        raise ConfigError(source, "fp16", "with backend 'onnx', fp16 is TensorRT's (its execution provider builds the "
                                          "engine in fp16); this ONNX Runtime has no TensorrtExecutionProvider, so "
                                          "leave fp16 off (CUDA runs fp32) or use backend 'torch'")
    out: list = []
    if TRT_PROVIDER in gpu:
        cache = trt_cache_dir()
        cache.mkdir(parents=True, exist_ok=True)
        out.append((TRT_PROVIDER, {"device_id": index, "trt_fp16_enable": "True" if fp16 else "False",
                                   "trt_engine_cache_enable": "True", "trt_engine_cache_path": str(cache)}))
    if CUDA_PROVIDER in gpu:
        out.append((CUDA_PROVIDER, {"device_id": index}))
    return out + [CPU_PROVIDER]


def ort_session(model_bytes_or_path, device: str, threads: int | None, source: str, fp16: bool = False):
    """An ONNX Runtime session on ``device`` (:func:`ort_providers`: on a GPU TensorRT first, in fp16 with
    ``fp16``), its intra-op pool not spinning (:func:`ort_spinning`); a :class:`ConfigError` naming ``source``
    when onnxruntime is missing, has no provider for ``device``, or cannot load the model."""
    try:
        import onnxruntime as ort
    except ImportError as e:  # optional dependency
        raise ConfigError(source, "backend", "backend 'onnx' needs the onnxruntime package (pip install onnxruntime)") from e
    providers = ort_providers(device, fp16, list(ort.get_available_providers()), source)
    so = ort.SessionOptions()
    if threads:
        so.intra_op_num_threads = int(threads)
        so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    if not ort_spinning(threads):
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    try:
        return ort.InferenceSession(model_bytes_or_path, sess_options=so, providers=providers)
    except Exception as e:  # noqa: BLE001 - onnxruntime raises its own exception types
        raise ConfigError(source, None, f"ONNX Runtime cannot load the model: {e}") from e


def onnx_input_size(sess, source: str) -> tuple[int, int]:
    """(W, H) of a session's fixed input; a :class:`ConfigError` for a dynamic one."""
    shape = sess.get_inputs()[0].shape
    if len(shape) != 4 or not all(isinstance(v, int) for v in shape[2:]):
        raise ConfigError(source, "imgsz", f"ONNX input shape {shape} is dynamic: give imgsz: [W, H] in the sidecar")
    return int(shape[3]), int(shape[2])
