"""Run the cone detector on images: backends, pre- and post-processing.

    det = Detector.load(default_model_path())  # backend "auto"; or "torch", "torchscript", "onnx"
    det.warmup()
    boxes = det.detect(bgr_cropped, crop)    # BOX_DTYPE records, FULL-image px
    det.timing                                # last frame's preprocess / forward / postprocess ms

Model files:

* our checkpoint (``*.pt``, see :mod:`.checkpoint`): any backend; TorchScript
  and ONNX Runtime are built from it at load time for the checkpoint's input size;
* TorchScript (``*.torchscript``, ``*.ts``) or ONNX (``*.onnx``) exported by us or
  by other YOLO tools: output ``(1, 4 + nc, N)`` (cx, cy, w, h in input px, then
  class scores), RGB 0..1 NCHW input, with a YAML sidecar next to it
  (``<stem>.yaml``: ``names:`` list or {id: name}, optional ``imgsz: [W, H]``);
  without a sidecar, the class names other YOLO tools embed (ONNX metadata,
  TorchScript ``config.txt``) are used.

The network input is the cropped band as it is (the car's 960x288); an image
whose size is not a multiple of 32 is padded right / bottom (said once). Fixed
size backends (TorchScript, ONNX) letterbox other sizes to their input size.
"""

from __future__ import annotations

import ast
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import torch
import yaml

from .. import records
from ..adapter import pin_opencv_threads
from ..classes import CLASS_NAMES
from ..checkpoint import RESTORE_HINT, Checkpoint, class_map_from_names, load_checkpoint
from ..crop import CropSpec
from ..errors import ConfigError
from ..model.decode import postprocess
from ..params import DEFAULT_BACKEND, DEFAULT_CONF, DEFAULT_IOU, DEFAULT_MAX_DET, RUNTIME_THREADS  # noqa: F401 - re-exported
from ..resources import models_dir

log = logging.getLogger(__name__)

#: File name of the shipped default model under ``models/``.
DEFAULT_MODEL_NAME = "cone_detector.pt"
BACKENDS = ("torch", "torchscript", "onnx")
#: What ``backend`` may be: a backend, or ``auto`` (:func:`resolve_backend`), the default everywhere.
BACKEND_CHOICES = ("auto", *BACKENDS)
PAD_VALUE = 114


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
    try:  # ONNX Runtime runs it; torch's exporter needs the onnx package to build it
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError:
        return "torch"
    return "onnx"


def default_model_path() -> Path:
    """``models/cone_detector.pt`` of the installed package (may not exist yet)."""
    return models_dir() / DEFAULT_MODEL_NAME


def round_up32(n: int) -> int:
    return int(-(-int(n) // 32) * 32)


def band_input_size(band_wh: tuple[int, int]) -> tuple[int, int]:
    """The network input (W, H) a checkpoint is built for to run a band of ``band_wh`` as it is:
    each side rounded up to a multiple of 32 (the band is padded, never scaled)."""
    return round_up32(band_wh[0]), round_up32(band_wh[1])


@dataclass(frozen=True)
class Letterbox:
    """How an image was fitted into the network input: scale, then pad right / bottom."""

    scale: float
    in_w: int
    in_h: int

    def boxes_to_image(self, boxes_in_px: np.ndarray, image_w: int, image_h: int) -> np.ndarray:
        """(N, 4) boxes in network-input px -> image px, clipped to the image (float32)."""
        b = np.asarray(boxes_in_px, dtype=np.float32).reshape(-1, 4) / np.float32(self.scale)
        b[:, 0::2] = b[:, 0::2].clip(0, image_w)
        b[:, 1::2] = b[:, 1::2].clip(0, image_h)
        return b


def letterbox(img: np.ndarray, in_w: int, in_h: int) -> tuple[np.ndarray, Letterbox]:
    """Fit ``img`` (h, w, 3) into (in_h, in_w, 3): scale to fit, pad right / bottom with grey."""
    h, w = img.shape[:2]
    r = min(in_w / w, in_h / h)
    if abs(r - 1.0) > 1e-9:
        nw, nh = min(in_w, round(w * r)), min(in_h, round(h * r))
        img = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_LINEAR if r > 1 else cv2.INTER_AREA)
    else:
        r = 1.0
    h2, w2 = img.shape[:2]
    if (h2, w2) != (in_h, in_w):
        img = cv2.copyMakeBorder(img, 0, in_h - h2, 0, in_w - w2, cv2.BORDER_CONSTANT, value=(PAD_VALUE,) * 3)
    return img, Letterbox(r, in_w, in_h)


def preprocess(bgr: np.ndarray, in_w: int, in_h: int) -> tuple[np.ndarray, Letterbox]:
    """BGR uint8 image -> the network input: letterboxed to (in_w, in_h), (1, 3, H, W) float32 RGB 0..1.

    The one preprocessing of every backend (and of int8 calibration, :mod:`.quantize`)."""
    img, lb = letterbox(bgr, in_w, in_h)
    return cv2.dnn.blobFromImage(img, 1.0 / 255.0, swapRB=True), lb


# -- backends: (1, 3, H, W) float32 RGB 0..1 -> (4 + nc, N) float32 numpy --------------------------


class _TorchRunner:
    def __init__(self, module: Callable, device: str, fp16: bool, channels_last: bool, bf16: bool = False):
        self.module, self.device, self.fp16, self.channels_last = module, torch.device(device), fp16, channels_last
        self.bf16 = bf16  # CPU bfloat16 autocast (weights stay fp32)

    def __call__(self, blob: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(blob).to(self.device)
        if self.channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        if self.fp16:
            x = x.half()
        with torch.inference_mode(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=self.bf16):
            y = self.module(x)
        if isinstance(y, (list, tuple)):
            y = y[0]
        return y[0].float().cpu().numpy()


class _OrtRunner:
    def __init__(self, session):
        self.session = session
        self.input_name = session.get_inputs()[0].name
        self.fp16 = session.get_inputs()[0].type == "tensor(float16)"

    def __call__(self, blob: np.ndarray) -> np.ndarray:
        x = blob.astype(np.float16) if self.fp16 else blob
        return np.asarray(self.session.run(None, {self.input_name: x})[0][0], dtype=np.float32)


def _ort_session(model_bytes_or_path, device: str, threads: int | None, source: str):
    try:
        import onnxruntime as ort
    except ImportError as e:  # optional dependency
        raise ConfigError(source, "backend", "backend 'onnx' needs the onnxruntime package (pip install onnxruntime)") from e
    so = ort.SessionOptions()
    if threads:
        so.intra_op_num_threads = int(threads)
        so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    providers = ["CPUExecutionProvider"]
    if device.startswith("cuda") and "CUDAExecutionProvider" in ort.get_available_providers():
        providers.insert(0, "CUDAExecutionProvider")
    try:
        return ort.InferenceSession(model_bytes_or_path, sess_options=so, providers=providers)
    except Exception as e:  # noqa: BLE001 - onnxruntime raises its own exception types
        raise ConfigError(source, None, f"ONNX Runtime cannot load the model: {e}") from e


def sidecar_path(model_path: str | Path) -> Path:
    """The YAML sidecar ``export`` writes for one exported file: ``<file name>.yaml`` (``m.onnx`` ->
    ``m.onnx.yaml``), so a TorchScript and an ONNX export to one stem keep one sidecar each."""
    model_path = Path(model_path)
    return model_path.with_name(model_path.name + ".yaml")


def find_sidecar(model_path: Path) -> Path | None:
    """The sidecar of an exported model: ``<file name>.yaml``, else ``<stem>.yaml`` (other YOLO tools, older
    exports); None when neither exists."""
    for side in (sidecar_path(model_path), model_path.with_suffix(".yaml")):
        if side.is_file():
            return side
    return None


def read_sidecar(model_path: Path) -> tuple[list[str], tuple[int, int] | None]:
    """Class names and optional input size from the sidecar of an exported model (:func:`find_sidecar`)."""
    side = find_sidecar(model_path)
    if side is None:
        raise ConfigError(str(sidecar_path(model_path)), None,
                          f"class names of {model_path.name} not found: neither embedded in the file nor in a sidecar "
                          f"{sidecar_path(model_path).name} or {model_path.with_suffix('.yaml').name} "
                          "(write `names: [blue_cone, ...]`, or export again: export embeds them)")
    try:
        doc = yaml.safe_load(side.read_text()) or {}
    except yaml.YAMLError as e:
        raise ConfigError(str(side), None, f"not valid YAML: {e}") from e
    names = doc.get("names") if isinstance(doc, dict) else None
    if isinstance(names, dict):
        try:
            names = [names[k] for k in sorted(names, key=int)]
        except (ValueError, TypeError) as e:
            raise ConfigError(str(side), "names", f"dict keys must be class indices 0..n-1: {e}") from e
    if not isinstance(names, list) or not names:
        raise ConfigError(str(side), "names", "must be a non-empty list of class names (or {index: name})")
    imgsz = doc.get("imgsz")
    if imgsz is not None:
        if not (isinstance(imgsz, (list, tuple)) and len(imgsz) == 2 and all(int(v) > 0 and int(v) % 32 == 0 for v in imgsz)):
            raise ConfigError(str(side), "imgsz", f"must be [W, H], positive multiples of 32, got {imgsz}")
        imgsz = (int(imgsz[0]), int(imgsz[1]))
    return [str(n) for n in names], imgsz


def _external_names(model_path: Path, embedded: dict) -> tuple[list[str], tuple[int, int] | None, str]:
    """Class names and input size of an exported model: the YAML sidecar if there is one, else the
    metadata ``export`` and other YOLO tools embed (``names`` as "{0: 'blue_cone', ...}", ``imgsz`` as [h, w])."""
    side = find_sidecar(model_path)
    if side is not None or "names" not in embedded:
        names, imgsz = read_sidecar(model_path)
        return names, imgsz, str(side)
    side = sidecar_path(model_path)
    src = f"{model_path}: embedded metadata"
    try:
        names = embedded["names"]
        names = ast.literal_eval(names) if isinstance(names, str) else names
        if isinstance(names, dict):
            names = [names[k] for k in sorted(names, key=int)]
        imgsz = embedded.get("imgsz")
        imgsz = ast.literal_eval(imgsz) if isinstance(imgsz, str) else imgsz
    except (ValueError, SyntaxError, KeyError, TypeError) as e:
        raise ConfigError(src, "names", f"cannot read the embedded class names ({e}); write a sidecar {side.name}") from e
    if not isinstance(names, (list, tuple)) or not names:
        raise ConfigError(src, "names", f"embedded class names are not a list or dict; write a sidecar {side.name}")
    size = (int(imgsz[1]), int(imgsz[0])) if isinstance(imgsz, (list, tuple)) and len(imgsz) == 2 else None  # [h, w]
    return [str(n) for n in names], size, src


def write_sidecar(model_path: Path, class_names: list[str], imgsz: tuple[int, int], extra: dict | None = None) -> Path:
    """Write ``<file name>.yaml`` (:func:`sidecar_path`) with the class names, ``imgsz: [W, H]`` and ``extra``."""
    side = sidecar_path(model_path)
    doc = {"names": list(class_names), "imgsz": [int(imgsz[0]), int(imgsz[1])], **(extra or {})}
    side.write_text(yaml.safe_dump(doc, sort_keys=False))
    return side


class Detector:
    """A loaded detector: image in, :data:`records.BOX_DTYPE` boxes out."""

    def __init__(
        self,
        run: Callable[[np.ndarray], np.ndarray],
        class_map: list[int],
        imgsz: tuple[int, int],
        fixed_size: bool,
        backend: str,
        source: str,
        conf: float = DEFAULT_CONF,
        iou: float = DEFAULT_IOU,
        max_det: int = DEFAULT_MAX_DET,
        checkpoint: Checkpoint | None = None,
    ):
        self._run = run
        self.class_map = np.asarray(class_map, dtype=np.uint8)
        self.num_classes = len(class_map)
        self.imgsz = (int(imgsz[0]), int(imgsz[1]))
        self.fixed_size = fixed_size
        self.backend = backend
        self.source = source
        self.conf, self.iou, self.max_det = float(conf), float(iou), int(max_det)
        self.checkpoint = checkpoint
        self.timing: dict[str, float] = {"preprocess_ms": 0.0, "forward_ms": 0.0, "postprocess_ms": 0.0}
        self._said: set[tuple] = set()
        self._checked_output = False

    @property
    def precision(self) -> str:
        """What the network computes in: ``fp32``, ``fp16`` (CUDA, or an fp16 ONNX file) or ``bf16`` (CPU autocast)."""
        run = self._run
        return "bf16" if getattr(run, "bf16", False) else ("fp16" if getattr(run, "fp16", False) else "fp32")

    # -- loading -----------------------------------------------------------------------------
    @classmethod
    def load_for_band(cls, path: str | Path, band_wh: tuple[int, int], **kw) -> "Detector":
        """Load for images of one band size (W, H), as the car feeds them: a checkpoint is built
        for the band's size rounded up to a multiple of 32 (fixed-size backends included), so the
        band is padded, never letterboxed into another size. Exported files keep their own size.
        ``kw`` as for :meth:`load`."""
        imgsz = band_input_size(band_wh) if Path(path).suffix == ".pt" else None
        return cls.load(path, imgsz=imgsz, **kw)

    def runs_band_as_is(self, band_wh: tuple[int, int]) -> bool:
        """False for a fixed-size network built from a checkpoint for another size than
        :func:`band_input_size` of the band: it would letterbox the band; :meth:`load_for_band`
        builds one that does not."""
        return not (self.fixed_size and self.checkpoint is not None) or tuple(self.imgsz) == band_input_size(band_wh)

    @classmethod
    def load(
        cls,
        path: str | Path,
        backend: str = DEFAULT_BACKEND,
        device: str = "cpu",
        fp16: bool = False,
        conf: float = DEFAULT_CONF,
        iou: float = DEFAULT_IOU,
        max_det: int = DEFAULT_MAX_DET,
        imgsz: tuple[int, int] | None = None,
        threads: int | None = None,
        bf16: bool = False,
    ) -> "Detector":
        """Load a model file for ``backend`` (see module doc; ``auto``: :func:`resolve_backend`).
        ``imgsz`` (W, H) overrides the input size of fixed-size backends; ``threads`` sets torch /
        ONNX Runtime intra-op threads (None: the library's default); ``bf16``: bfloat16 autocast on
        the CPU (backend torch, a checkpoint), fast where the CPU has native bf16."""
        path = Path(path)
        src = str(path)
        if backend not in BACKEND_CHOICES:
            raise ConfigError(src, "backend", f"unknown backend {backend!r}; choose one of {', '.join(BACKEND_CHOICES)}")
        backend = resolve_backend(backend, path, device, bf16=bf16, fp16=fp16)
        if device.startswith("cuda") and not torch.cuda.is_available():
            raise ConfigError(src, "device", f"device {device!r} requested but CUDA is not available")
        if fp16 and not device.startswith("cuda"):
            raise ConfigError(src, "fp16", "fp16 needs a CUDA device (CPU half precision is slower than fp32)")
        if threads:
            torch.set_num_threads(int(threads))
        pin_opencv_threads()
        if not path.is_file():
            raise ConfigError(src, None, f"model file not found; {RESTORE_HINT}")
        kw = dict(conf=conf, iou=iou, max_det=max_det)
        suffix = path.suffix.lower()
        if bf16 and suffix in (".torchscript", ".ts", ".onnx"):
            raise ConfigError(src, "bf16", "bf16 runs a checkpoint (.pt) with backend 'torch', not an exported model")
        if suffix in (".torchscript", ".ts", ".onnx"):
            side = find_sidecar(path) or sidecar_path(path)
            if suffix == ".onnx":
                if backend != "onnx":
                    raise ConfigError(src, "backend", f"an ONNX file runs with backend 'onnx', not {backend!r}")
                sess = _ort_session(str(path), device, threads, src)
                embedded = dict(sess.get_modelmeta().custom_metadata_map)
                names, side_imgsz, names_src = _external_names(path, embedded)
                size = imgsz or side_imgsz or _onnx_input_size(sess, src)
                det = cls(_OrtRunner(sess), class_map_from_names(names, names_src), size, True, "onnx", src, **kw)
            else:
                if backend != "torchscript":
                    raise ConfigError(src, "backend", f"a TorchScript file runs with backend 'torchscript', not {backend!r}")
                extra = {"config.txt": ""}
                try:
                    module = torch.jit.load(str(path), map_location=device, _extra_files=extra).eval()
                except (RuntimeError, ValueError) as e:
                    raise ConfigError(src, None, f"not a readable TorchScript file: {e}") from e
                try:
                    embedded = json.loads(extra["config.txt"]) if extra["config.txt"] else {}
                except (json.JSONDecodeError, UnicodeDecodeError):
                    embedded = {}
                names, side_imgsz, names_src = _external_names(path, embedded)
                if fp16:
                    module = module.half()
                size = imgsz or side_imgsz
                if size is None:
                    raise ConfigError(str(side), "imgsz", "TorchScript models need imgsz: [W, H] in the sidecar")
                det = cls(_TorchRunner(module, device, fp16, False), class_map_from_names(names, names_src), size, True,
                          "torchscript", src, **kw)
            det._check_output_shape()
            return det

        return cls.from_checkpoint(load_checkpoint(path), backend, device, fp16, imgsz=imgsz, threads=threads, bf16=bf16, **kw)

    @classmethod
    def from_checkpoint(
        cls,
        ck: Checkpoint,
        backend: str = DEFAULT_BACKEND,
        device: str = "cpu",
        fp16: bool = False,
        imgsz: tuple[int, int] | None = None,
        threads: int | None = None,
        bf16: bool = False,
        **kw,
    ) -> "Detector":
        """A detector from a loaded checkpoint (or one made in memory, see :meth:`from_model`)."""
        backend = resolve_backend(backend, None, device, bf16=bf16, fp16=fp16)
        if bf16 and (backend != "torch" or device != "cpu" or fp16):
            raise ConfigError(ck.path, "bf16", f"bf16 is CPU autocast for backend 'torch' (got backend {backend!r}, "
                              f"device {device!r}{', fp16' if fp16 else ''}); on a GPU use fp16")
        class_map = class_map_from_names(ck.class_names, ck.path)
        size = (int(imgsz[0]), int(imgsz[1])) if imgsz else ck.imgsz
        model = ck.build_model()
        if backend == "onnx":
            from .export import onnx_bytes

            sess = _ort_session(onnx_bytes(model, size), device, threads, ck.path)
            return cls(_OrtRunner(sess), class_map, size, True, "onnx", ck.path, checkpoint=ck, **kw)
        model = model.fuse().to(device)
        if fp16:
            model = model.half()
        if backend == "torchscript":
            from .export import trace

            module = trace(model, size, device=device, fp16=fp16)
            return cls(_TorchRunner(module, device, fp16, False), class_map, size, True, "torchscript", ck.path, checkpoint=ck, **kw)
        if backend != "torch":
            raise ConfigError(ck.path, "backend", f"unknown backend {backend!r}; choose one of {', '.join(BACKEND_CHOICES)}")
        model = model.to(memory_format=torch.channels_last)
        return cls(_TorchRunner(model, device, fp16, True, bf16=bf16), class_map, size, False, "torch", ck.path, checkpoint=ck, **kw)

    @classmethod
    def from_model(cls, model, imgsz: tuple[int, int], backend: str = DEFAULT_BACKEND, **kw) -> "Detector":
        """A detector around an in-memory :class:`ConeYOLO` (benchmarks, tests); classes in project order."""
        ck = Checkpoint(model.cfg, list(CLASS_NAMES[: model.cfg.num_classes]), tuple(imgsz),
                        {k: v.detach().clone() for k, v in model.state_dict().items()}, path=f"<{model.cfg.name} in memory>")
        return cls.from_checkpoint(ck, backend, imgsz=imgsz, **kw)

    def _check_output_shape(self) -> None:
        """Run one blank input; an output that is not (4 + nc, N) is a :class:`ConfigError`."""
        w, h = self.imgsz
        try:
            out = self._run(np.zeros((1, 3, h, w), np.float32))
        except Exception as e:  # noqa: BLE001 - foreign models fail in many ways
            raise ConfigError(self.source, None, f"model does not run on a (1, 3, {h}, {w}) input: {e}") from e
        if out.ndim != 2 or out.shape[0] != 4 + self.num_classes:
            raise ConfigError(
                self.source, "output",
                f"expected output (1, 4 + {self.num_classes}, N) for {self.num_classes} classes, got (1, {', '.join(map(str, out.shape))})",
            )

    def describe(self) -> str:
        """One line for logs: file, backend, input size, classes, thresholds."""
        arch = f"size {self.checkpoint.cfg.name}, " if self.checkpoint else ""
        return (f"{self.source} ({arch}backend {self.backend}, input {self.imgsz[0]}x{self.imgsz[1]}, "
                f"{self.num_classes} classes, conf {self.conf}, iou {self.iou}, max_det {self.max_det})")

    # -- running -----------------------------------------------------------------------------
    def warmup(self, n: int = 3) -> None:
        """Run ``n`` blank frames at the input size (first-call allocations, JIT)."""
        w, h = self.imgsz
        for _ in range(n):
            self._run(np.zeros((1, 3, h, w), np.float32))

    def _say_once(self, key: tuple, msg: str) -> None:
        if key not in self._said:
            self._said.add(key)
            log.warning(msg)

    def input_size_for(self, w: int, h: int) -> tuple[int, int]:
        """Network input (W, H) used for an image of w x h as it is (no scaling if possible)."""
        if self.fixed_size:
            return self.imgsz
        return band_input_size((w, h))

    def infer(self, bgr: np.ndarray, in_size: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Detect in a BGR image (h, w, 3) uint8 -> ((K, 4) float32 x1 y1 x2 y2 in THIS image's px,
        (K,) float32 scores, (K,) uint8 project class ids). Fills :attr:`timing`."""
        if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
            raise ValueError(f"expected a (h, w, 3) uint8 BGR image, got {bgr.shape} {bgr.dtype}")
        t0 = time.perf_counter()
        h, w = bgr.shape[:2]
        in_w, in_h = in_size or self.input_size_for(w, h)
        if (in_w, in_h) != (w, h):
            if not self.fixed_size:
                self._say_once(("pad", w, h), f"image {w}x{h} is not a multiple of 32: padded to {in_w}x{in_h}")
            elif in_size is None:
                how = "padded" if min(in_w / w, in_h / h) == 1.0 else "letterboxed"  # scale 1: as the padding above
                self._say_once(("fit", w, h), f"image {w}x{h} {how} to the model input {in_w}x{in_h}")
        blob, lb = preprocess(bgr, in_w, in_h)
        t1 = time.perf_counter()
        pred = self._run(blob)
        t2 = time.perf_counter()
        boxes, scores, cls = postprocess(pred, self.conf, self.iou, self.max_det)
        boxes = lb.boxes_to_image(boxes, w, h)
        t3 = time.perf_counter()
        self.timing = {"preprocess_ms": (t1 - t0) * 1e3, "forward_ms": (t2 - t1) * 1e3, "postprocess_ms": (t3 - t2) * 1e3}
        return boxes, scores, self.class_map[cls]

    def detect(self, bgr_cropped: np.ndarray, crop: CropSpec) -> np.ndarray:
        """Boxes in a cropped (and downscaled) band -> :data:`records.BOX_DTYPE`, FULL-image px."""
        boxes, scores, cls = self.infer(bgr_cropped)
        return records.boxes_from_arrays(crop.boxes_to_full(boxes), scores, cls)

    def detect_image(self, bgr: np.ndarray) -> np.ndarray:
        """Boxes in an arbitrary image, letterboxed to the model input size -> records in its px."""
        boxes, scores, cls = self.infer(bgr, in_size=self.imgsz)
        return records.boxes_from_arrays(boxes, scores, cls)

    def raw(self, blob: np.ndarray) -> np.ndarray:
        """(1, 3, H, W) float32 RGB 0..1 -> (4 + nc, N) network output (for tests and export checks)."""
        return self._run(np.ascontiguousarray(blob, dtype=np.float32))


def _onnx_input_size(sess, source: str) -> tuple[int, int]:
    shape = sess.get_inputs()[0].shape
    if len(shape) != 4 or not all(isinstance(v, int) for v in shape[2:]):
        raise ConfigError(source, "imgsz", f"ONNX input shape {shape} is dynamic: give imgsz: [W, H] in the sidecar")
    return int(shape[3]), int(shape[2])


def detect_one(det, img: np.ndarray, name: str, crop: tuple[int, ...] | None = None, downscale: int = 1,
               imgsz: tuple[int, int] | None = None) -> tuple[np.ndarray, float]:
    """Boxes (``BOX_DTYPE``, the image's px) of one full BGR image, as ``detect`` does it: with ``crop``
    (V0,V1[,U0,U1]) the band is cut and downscaled as on the car, else letterboxed to ``imgsz`` or the
    model input; and the model input px per image px (the prediction file's ``input_scale``).
    Used by ``detect`` and ``bench table``."""
    from ..adapter import crop_bgr
    from ..crop import CropSpec

    h, w = img.shape[:2]
    if crop:
        v0, v1, u0, u1 = crop if len(crop) == 4 else (*crop, 0, w)
        spec = CropSpec(v0, v1, u0, u1, downscale)
        spec.validate(w, h, f"--crop for {name}")
        return det.detect(crop_bgr(img, spec), spec), 1.0 / downscale
    if imgsz:
        from ..records import boxes_from_arrays

        b, s, c = det.infer(img, in_size=imgsz)
        return boxes_from_arrays(b, s, c), min(imgsz[0] / w, imgsz[1] / h)
    return det.detect_image(img), min(det.imgsz[0] / w, det.imgsz[1] / h)
