"""Run the cone detector on images: backends, pre- and post-processing.

    det = Detector.load(default_model_path())  # backend "auto"; or "torch", "torchscript", "onnx"
    det.warmup()
    boxes = det.detect(bgr_cropped, crop)    # BOX_DTYPE records, FULL-image px
    det.timing                                # last frame's preprocess / forward / postprocess ms

Model files:

* our checkpoint (``*.pt``, see :mod:`.checkpoint`): any backend; TorchScript
  is built from it at load time for the checkpoint's (or the band's) input size, ONNX Runtime's graph is
  exported once and kept in the ONNX cache (:mod:`.onnx_cache`), so a start with the cache warm imports
  no torch (the torch side: :mod:`.torch_backend`);
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

import json
import logging
import time
from pathlib import Path
from typing import Callable

import numpy as np

from .. import records
from ..adapter import crop_bgr, pin_opencv_threads
from ..classes import CLASS_NAMES, class_map_from_names
from ..crop import CropSpec
from ..errors import ConfigError
from ..model.postprocess import postprocess
from ..params import DEFAULT_BACKEND, DEFAULT_CONF, DEFAULT_IOU, DEFAULT_MAX_DET
from ..records import boxes_from_arrays
from ..resources import RESTORE_HINT
from .backends import BACKEND_CHOICES, ONNX_OPSET, OrtRunner, onnx_input_size, ort_session, resolve_backend
from .model_files import external_names, find_sidecar, sidecar_path
from .onnx_cache import DETECTOR, ModelInfo, detector_params, detector_problem, load_graph
from .preprocess import band_input_size, preprocess

log = logging.getLogger(__name__)


def _torch():
    """:mod:`.torch_backend` (torch), imported where a backend or an export needs it, never on a warm ONNX start."""
    import cone_perception.detector.torch_backend as torch_backend  # torch: heavy, absent from a warm ONNX start

    return torch_backend


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

    @property
    def runs_on(self) -> str:
        """Where the network runs: ONNX Runtime's first execution provider (``TensorRT``, ``CUDA``, ``CPU``) or the
        torch device (``cpu``, ``cuda:0``)."""
        provider = getattr(self._run, "provider", None)
        if provider is not None:
            return str(provider).removesuffix("ExecutionProvider").replace("Tensorrt", "TensorRT")
        return str(getattr(self._run, "device", "cpu"))

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
        if fp16 and not device.startswith("cuda"):
            raise ConfigError(src, "fp16", "fp16 needs a CUDA device (CPU half precision is slower than fp32)")
        if backend != "onnx":  # onnx: a GPU it cannot reach is ort_providers' error
            _torch().prepare_torch(device, threads, src)
        pin_opencv_threads()
        if not path.is_file():
            raise ConfigError(src, None, f"model file not found; {RESTORE_HINT}")
        kw = dict(conf=conf, iou=iou, max_det=max_det)
        suffix = path.suffix.lower()
        if bf16 and suffix in (".torchscript", ".ts", ".onnx"):
            raise ConfigError(src, "bf16", "bf16 runs a checkpoint (.pt) with backend 'torch', not an exported model")
        if suffix == ".onnx":
            det = cls._load_onnx(path, backend, device, imgsz, threads, kw, fp16)
        elif suffix in (".torchscript", ".ts"):
            det = cls._load_torchscript(path, backend, device, fp16, imgsz, kw)
        elif backend == "onnx" and not bf16:
            return cls._load_checkpoint_onnx(path, device, fp16, imgsz, threads, kw)
        else:
            ck = _torch().load_checkpoint(path)
            return cls.from_checkpoint(ck, backend, device, fp16, imgsz=imgsz, threads=threads, bf16=bf16, **kw)
        det._check_output_shape()
        return det

    @classmethod
    def _load_checkpoint_onnx(cls, path: Path, device: str, fp16: bool, imgsz: tuple[int, int] | None,
                              threads: int | None, kw: dict) -> "Detector":
        """A checkpoint on ONNX Runtime: its graph for ``imgsz`` from the ONNX cache (:func:`~.onnx_cache.load_graph`:
        exported with torch and cached where missing or not verifying), the class names and input size with it."""
        src = str(path)
        sess, info, _ = load_graph(path, DETECTOR, detector_params(imgsz, ONNX_OPSET),
                                   lambda: _torch().checkpoint_graph(path, imgsz),
                                   lambda graph: ort_session(graph, device, threads, src, fp16), detector_problem, src)
        ck = ModelInfo.from_info(info, src)
        return cls(OrtRunner(sess), class_map_from_names(ck.class_names, src), ck.imgsz, True, "onnx", src,
                   checkpoint=ck, **kw)

    @classmethod
    def _load_onnx(cls, path: Path, backend: str, device: str, imgsz: tuple[int, int] | None, threads: int | None,
                   kw: dict, fp16: bool = False) -> "Detector":
        """An ONNX file on ONNX Runtime; names and size from the sidecar, the embedded metadata or the graph."""
        src = str(path)
        if backend != "onnx":
            raise ConfigError(src, "backend", f"an ONNX file runs with backend 'onnx', not {backend!r}")
        sess = ort_session(src, device, threads, src, fp16)
        embedded = dict(sess.get_modelmeta().custom_metadata_map)
        names, side_imgsz, names_src = external_names(path, embedded)
        size = imgsz or side_imgsz or onnx_input_size(sess, src)
        return cls(OrtRunner(sess), class_map_from_names(names, names_src), size, True, "onnx", src, **kw)

    @classmethod
    def _load_torchscript(cls, path: Path, backend: str, device: str, fp16: bool, imgsz: tuple[int, int] | None,
                          kw: dict) -> "Detector":
        """A TorchScript file; names and size from the sidecar or its embedded ``config.txt``."""
        src = str(path)
        if backend != "torchscript":
            raise ConfigError(src, "backend", f"a TorchScript file runs with backend 'torchscript', not {backend!r}")
        runner, config_txt = _torch().load_torchscript(src, device, fp16)
        try:
            embedded = json.loads(config_txt) if config_txt else {}
        except (json.JSONDecodeError, UnicodeDecodeError):
            embedded = {}
        names, side_imgsz, names_src = external_names(path, embedded)
        size = imgsz or side_imgsz
        if size is None:
            side = find_sidecar(path) or sidecar_path(path)
            raise ConfigError(str(side), "imgsz", "TorchScript models need imgsz: [W, H] in the sidecar")
        return cls(runner, class_map_from_names(names, names_src), size, True, "torchscript", src, **kw)

    @classmethod
    def from_checkpoint(
        cls,
        ck,
        backend: str = DEFAULT_BACKEND,
        device: str = "cpu",
        fp16: bool = False,
        imgsz: tuple[int, int] | None = None,
        threads: int | None = None,
        bf16: bool = False,
        **kw,
    ) -> "Detector":
        """A detector from a loaded :class:`~cone_perception.model.checkpoint.Checkpoint` (or one made in memory, see
        :meth:`from_model`); backend ``onnx`` exports it in memory (a checkpoint file: :meth:`load`, cached)."""
        backend = resolve_backend(backend, None, device, bf16=bf16, fp16=fp16)
        if bf16 and (backend != "torch" or device != "cpu" or fp16):
            raise ConfigError(ck.path, "bf16", f"bf16 is CPU autocast for backend 'torch' (got backend {backend!r}, "
                              f"device {device!r}{', fp16' if fp16 else ''}); on a GPU use fp16")
        tb = _torch()
        if bf16:
            if not tb.native_bf16():
                log.warning("bf16: this CPU has no native bfloat16 (AVX512-BF16 or AMX), so autocast emulates it "
                            "and runs slower than fp32; leave bf16 off here (the boxes are the same)")
        class_map = class_map_from_names(ck.class_names, ck.path)
        size = (int(imgsz[0]), int(imgsz[1])) if imgsz else ck.imgsz
        run, fixed = tb.checkpoint_runner(ck, backend, device, fp16, size, threads, bf16)
        return cls(run, class_map, size, fixed, backend, ck.path, checkpoint=ck, **kw)

    @classmethod
    def from_model(cls, model, imgsz: tuple[int, int], backend: str = DEFAULT_BACKEND, **kw) -> "Detector":
        """A detector around an in-memory :class:`ConeYOLO` (benchmarks, tests); classes in project order."""
        ck = _torch().Checkpoint(model.cfg, list(CLASS_NAMES[: model.cfg.num_classes]), tuple(imgsz),
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


def detect_one(det, img: np.ndarray, name: str, crop: tuple[int, ...] | None = None, downscale: int = 1,
               imgsz: tuple[int, int] | None = None, far=None) -> tuple[np.ndarray, float, np.ndarray | None]:
    """Boxes (``BOX_DTYPE``, the image's px) of one full BGR image, as ``detect`` does it: with ``crop``
    (V0,V1[,U0,U1]) the band is cut and downscaled as on the car, else letterboxed to ``imgsz`` or the
    model input; the model input px per image px (the prediction file's ``input_scale``); and which of the
    boxes the far strip drew ((N,) bool, None without one: the prediction file's ``far``).
    ``far``: a :class:`~.farband.FarBand` whose full-resolution strip runs too (with ``crop``).
    Used by ``detect`` and ``bench table``."""
    h, w = img.shape[:2]
    if crop:
        v0, v1, u0, u1 = crop if len(crop) == 4 else (*crop, 0, w)
        spec = CropSpec(v0, v1, u0, u1, downscale)
        spec.validate(w, h, f"--crop for {name}")
        boxes = det.detect(crop_bgr(img, spec), spec)
        if far is None:
            return boxes, 1.0 / downscale, None
        boxes, drawn = far.merged(boxes, crop_bgr(img, far.crop))
        return boxes, 1.0 / downscale, drawn
    if imgsz:
        b, s, c = det.infer(img, in_size=imgsz)
        return boxes_from_arrays(b, s, c), min(imgsz[0] / w, imgsz[1] / h), None
    return det.detect_image(img), min(det.imgsz[0] / w, det.imgsz[1] / h), None
