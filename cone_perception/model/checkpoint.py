"""The detector checkpoint: one file with weights, architecture, class names,
input size, training-data summary and metrics; validated on load.

Layout (a ``torch.save`` dict)::

    format: "cone_perception.detector", version: 1
    arch: ModelConfig.to_dict()        class_names: [str] (model class order)
    imgsz: [W, H] (input px)           state_dict: weights (EMA when trained)
    data: {...} training data summary  metrics: {...} validation metrics
    train: {...} optimizer / RNG state for exact resume (``last.pt`` only)

Loading cannot run code: ``torch.load(weights_only=True)`` with numpy arrays, dtypes and scalars as
the only other types allowed (:func:`safe_torch_load`); what :func:`save_checkpoint` writes (tensors,
lists, dicts, strings, numbers, numpy values) loads as it is, so no migration is needed. A file
that names anything else, random bytes or a truncated zip is a :class:`ConfigError` naming the
file; so are NaN or inf weights (:func:`check_finite`).
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..classes import CLASS_NAMES, class_map_from_names
from ..errors import ConfigError
from ..resources import RESTORE_HINT  # noqa: F401 (re-exported: what a missing or bad model file's error advises)
from . import ConeYOLO, ModelConfig

FORMAT = "cone_perception.detector"
VERSION = 1
REQUIRED_KEYS = ("format", "version", "arch", "class_names", "imgsz", "state_dict")



@dataclass
class Checkpoint:
    cfg: ModelConfig
    class_names: list[str]
    imgsz: tuple[int, int]  # (W, H) input px
    state_dict: dict[str, torch.Tensor]
    data: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    train: dict | None = None
    path: str = ""

    def build_model(self) -> ConeYOLO:
        """The model with these weights (eval mode, not fused)."""
        model = ConeYOLO(self.cfg)
        try:
            model.load_state_dict(self.state_dict, strict=True)
        except RuntimeError as e:
            first = str(e).splitlines()[0:3]
            raise ConfigError(self.path, "state_dict", f"weights do not fit architecture {self.cfg.name!r}: {' '.join(first)}") from e
        return model.eval()


def load_matching(model: torch.nn.Module, state_dict: dict[str, torch.Tensor]) -> tuple[int, list[str]]:
    """Copy into ``model`` every tensor of ``state_dict`` whose name and shape match one of its own
    (a warm start across architectures, e.g. ``p`` -> ``p2``); returns (tensors loaded, names of the
    model's tensors left as they were)."""
    own = model.state_dict()
    fits = {k: v for k, v in state_dict.items() if k in own and tuple(own[k].shape) == tuple(v.shape)}
    model.load_state_dict(fits, strict=False)
    return len(fits), sorted(k for k in own if k not in fits)


def save_checkpoint(
    path: str | Path,
    model: torch.nn.Module,
    imgsz: tuple[int, int],
    class_names: list[str] | tuple[str, ...] = CLASS_NAMES,
    data: dict | None = None,
    metrics: dict | None = None,
    train: dict | None = None,
) -> None:
    """Write ``model`` (a :class:`ConeYOLO`, not fused) and its description to ``path`` (atomic)."""
    if getattr(model, "fused", False):
        raise ValueError("cannot save a fused model: save the training model")
    obj: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "arch": model.cfg.to_dict(),
        "class_names": list(class_names),
        "imgsz": [int(imgsz[0]), int(imgsz[1])],
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "data": data or {},
        "metrics": metrics or {},
    }
    if train is not None:
        obj["train"] = train
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def _safe_globals() -> list:
    """The only classes and functions a checkpoint may name besides torch's own tensors and
    containers: numpy arrays, dtypes and scalars (the numpy RNG state of ``last.pt``, numpy numbers
    in metrics). None of them calls anything else: an array's contents are plain data."""
    try:
        from numpy._core import multiarray  # numpy >= 2
    except ImportError:  # numpy 1.x
        from numpy.core import multiarray
    out = [np.ndarray, np.dtype, multiarray._reconstruct, multiarray.scalar]
    out += sorted({type(np.dtype(t)) for t in "?bBhHiIlLqQefdgFDGUS"}, key=str)  # numpy >= 1.25 dtype classes
    return out


def safe_torch_load(path: str | Path) -> Any:
    """``torch.load`` that cannot run code: ``weights_only=True`` (tensors, containers, numbers,
    strings) plus :func:`_safe_globals`. Anything else (a pickle naming another global: a crafted
    file, random bytes, a truncated zip) is a :class:`ConfigError` naming the file."""
    src = str(path)
    try:
        with torch.serialization.safe_globals(_safe_globals()):
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        named = next((ln for ln in lines if "GLOBAL" in ln), None)
        if named:
            raise ConfigError(src, None, "refused: not a plain-data checkpoint (loading it would call what it "
                                         f"names: {named[:200]}); {RESTORE_HINT}") from None
        why = next((ln for ln in lines if ln.startswith("Unsupported")), "not a pickle of plain data")
        raise ConfigError(src, None, f"not a readable checkpoint (corrupt: {why[:200]}); {RESTORE_HINT}") from None
    except Exception as e:  # noqa: BLE001 - zip, EOF, OS, runtime errors: all mean "not a readable checkpoint"
        raise ConfigError(src, None, f"not a readable checkpoint (truncated or corrupt: {type(e).__name__}: "
                                     f"{str(e).strip()[:200]}); {RESTORE_HINT}") from None


def check_finite(state_dict: Any, source: str) -> None:
    """:class:`ConfigError` naming the first weight that is not a tensor or holds NaN or inf."""
    if not isinstance(state_dict, dict):
        raise ConfigError(source, "state_dict", f"must be a mapping of tensors, got {type(state_dict).__name__}")
    for k, v in state_dict.items():
        if not isinstance(v, torch.Tensor):
            raise ConfigError(source, f"state_dict.{k}", f"must be a tensor, got {type(v).__name__}")
        if v.is_floating_point() and not bool(torch.isfinite(v).all()):
            n = int((~torch.isfinite(v)).sum())
            raise ConfigError(source, f"state_dict.{k}", f"{n} of {v.numel()} weights are NaN or inf; {RESTORE_HINT}")


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read and validate a checkpoint; every problem is a :class:`ConfigError` naming file and field."""
    src = str(path)
    p = Path(path)
    if not p.is_file():
        raise ConfigError(src, None, f"model file not found; {RESTORE_HINT}")
    obj = safe_torch_load(p)
    if not isinstance(obj, dict) or obj.get("format") != FORMAT:
        raise ConfigError(src, "format", f"not a cone_perception detector checkpoint (expected format {FORMAT!r})")
    missing = [k for k in REQUIRED_KEYS if k not in obj]
    if missing:
        raise ConfigError(src, missing[0], f"missing from checkpoint (required: {', '.join(REQUIRED_KEYS)})")
    if obj["version"] != VERSION:
        raise ConfigError(src, "version", f"checkpoint version {obj['version']} is not supported (this code reads {VERSION})")
    try:
        cfg = ModelConfig.from_dict(dict(obj["arch"]))
    except (ValueError, TypeError) as e:
        raise ConfigError(src, "arch", str(e)) from e
    names = [str(n) for n in obj["class_names"]]
    if len(names) != cfg.num_classes:
        raise ConfigError(src, "class_names", f"{len(names)} names for a model of {cfg.num_classes} classes")
    class_map_from_names(names, src)
    imgsz = obj["imgsz"]
    if len(imgsz) != 2 or any(int(v) <= 0 or int(v) % 32 for v in imgsz):
        raise ConfigError(src, "imgsz", f"must be [W, H], positive multiples of 32, got {imgsz}")
    ck = Checkpoint(
        cfg=cfg,
        class_names=names,
        imgsz=(int(imgsz[0]), int(imgsz[1])),
        state_dict=obj["state_dict"],
        data=dict(obj.get("data") or {}),
        metrics=dict(obj.get("metrics") or {}),
        train=obj.get("train"),
        path=src,
    )
    check_finite(ck.state_dict, src)
    ck.build_model()  # validates the weights against the architecture
    return ck
