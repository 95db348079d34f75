"""The ONNX graphs of the torch model files, cached, so that a node on ONNX Runtime starts without torch (issue 43).

ONNX Runtime runs a checkpoint (``.pt``: the band's and the far strip's detector, the far strip's verifier) as an
ONNX graph exported from it by torch. Exporting imports torch (1.5 s on a desktop CPU, more on a Jetson, and
300 MB of memory) and takes a second or more itself; this cache keeps each export on disk, so a start reads the
graph and the little the model needs besides (class names, input size, the verifier's thresholds) from it, and
imports no torch at all.

Where: :func:`onnx_cache_dir` (``$XDG_CACHE_HOME`` or ``~/.cache``, then ``cone_perception/onnx``, beside the
TensorRT engines). One entry per model file content, kind and export parameters: ``<stem>.onnx`` (the graph) and
``<stem>.json`` (what it is: the model file's sha256, the export parameters, the package and export versions, the
graph's own sha256 and size, and the model's description), the stem
``<kind>-<model sha256, 16 hex>-<export parameters' hash, 8 hex>``.

Written by the first start that misses it (or ``cone-perception export --cache`` before driving), each file
atomically (a temporary file in the folder, then renamed over), the graph first and its description last, so a
description always names a complete graph. A changed model file has another content hash: another entry.

Never trusted unverified: an entry whose description is unreadable or of another format, another model (its
sha256), other export parameters, another package or export version, whose graph is missing, truncated or changed
(size, sha256), that ONNX Runtime cannot load, or whose input is not the one expected, is rebuilt from the model
file with a warning naming the file and the reason (that start imports torch). A cache folder that cannot be
written: the graph is exported in memory at each start, as before the cache, with one warning naming the folder.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from .. import __version__
from ..errors import ConfigError
from ..model.config import ModelConfig
from ..resources import user_cache_dir

log = logging.getLogger(__name__)

#: What a description's ``format`` says.
CACHE_FORMAT = "cone_perception.onnx_cache"
#: The version of what the cache's exports write (the graph, the description): raise it when either changes, so
#: entries of the older export are rebuilt (they do not verify).
EXPORT_VERSION = 1
#: The kinds of model file the cache exports.
DETECTOR, VERIFIER = "detector", "verifier"

_unwritable_said: set[str] = set()  # folders already warned about (one warning each per process)


def onnx_cache_dir() -> Path:
    """The cache's folder: :func:`~cone_perception.resources.user_cache_dir` / ``onnx``."""
    return user_cache_dir() / "onnx"


def file_sha256(path: str | Path) -> str:
    """The sha256 of a file's bytes, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass(frozen=True)
class GraphKey:
    """What one cache entry is of: the model file's content (sha256), its kind and the export parameters
    (JSON values: input size, opset, ...)."""

    kind: str
    model_sha256: str
    params: dict

    @property
    def stem(self) -> str:
        ph = hashlib.sha256(json.dumps(self.params, sort_keys=True).encode()).hexdigest()[:8]
        return f"{self.kind}-{self.model_sha256[:16]}-{ph}"

    def description(self, model: Path, graph: bytes, info: dict) -> dict:
        """The ``<stem>.json`` of this key's entry holding ``graph`` and ``info``."""
        return {"format": CACHE_FORMAT, "export_version": EXPORT_VERSION, "package": __version__, "kind": self.kind,
                "model": str(model), "model_sha256": self.model_sha256, "params": self.params,
                "onnx_sha256": hashlib.sha256(graph).hexdigest(), "onnx_bytes": len(graph), "info": info}


@dataclass(frozen=True)
class CachedGraph:
    """A cache entry's files (:func:`entry_paths`)."""

    onnx: Path
    description: Path


def entry_paths(key: GraphKey, folder: Path | None = None) -> CachedGraph:
    """The files of ``key``'s entry in ``folder`` (default :func:`onnx_cache_dir`)."""
    folder = onnx_cache_dir() if folder is None else Path(folder)
    return CachedGraph(folder / f"{key.stem}.onnx", folder / f"{key.stem}.json")


def read_entry(key: GraphKey, paths: CachedGraph) -> tuple[bytes | None, dict | None, str | None]:
    """(graph, info, None) of a verified entry; (None, None, why) of one that does not verify; (None, None, None)
    where there is none."""
    if not paths.description.exists() and not paths.onnx.exists():
        return None, None, None
    try:
        meta = json.loads(paths.description.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None, None, "its description is missing"
    except (OSError, ValueError) as e:
        return None, None, f"its description is unreadable ({type(e).__name__})"
    if not isinstance(meta, dict) or meta.get("format") != CACHE_FORMAT:
        return None, None, "its description is not one of this cache"
    if meta.get("export_version") != EXPORT_VERSION or meta.get("package") != __version__:
        return None, None, (f"written by cone_perception {meta.get('package')} (export version "
                            f"{meta.get('export_version')}), this is {__version__} (export version {EXPORT_VERSION})")
    if meta.get("kind") != key.kind or meta.get("model_sha256") != key.model_sha256:
        return None, None, f"it is of another model ({meta.get('kind')} {str(meta.get('model_sha256'))[:16]})"
    if meta.get("params") != key.params:
        return None, None, f"it was exported with {meta.get('params')}, not {key.params}"
    if not isinstance(meta.get("info"), dict):
        return None, None, "its description lacks the model's info"
    try:
        graph = paths.onnx.read_bytes()
    except OSError as e:
        return None, None, f"its graph is unreadable ({type(e).__name__})"
    if len(graph) != meta.get("onnx_bytes") or hashlib.sha256(graph).hexdigest() != meta.get("onnx_sha256"):
        return None, None, (f"its graph is truncated or changed ({len(graph)} bytes, sha256 "
                            f"{hashlib.sha256(graph).hexdigest()[:16]}; written: {meta.get('onnx_bytes')} bytes, "
                            f"{str(meta.get('onnx_sha256'))[:16]})")
    return graph, meta["info"], None


def _write_atomic(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_entry(key: GraphKey, paths: CachedGraph, model: Path, graph: bytes, info: dict) -> bool:
    """Write ``key``'s entry (the graph, then its description; each atomically); False, with one warning per
    folder naming it, where the folder cannot be written."""
    folder = paths.onnx.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        _write_atomic(paths.onnx, graph)
        _write_atomic(paths.description, json.dumps(key.description(model, graph, info), indent=1).encode())
        return True
    except OSError as e:
        if str(folder) not in _unwritable_said:
            _unwritable_said.add(str(folder))
            log.warning(f"the ONNX cache folder {folder} cannot be written ({type(e).__name__}: {e.strerror or e}): "
                        "the models are exported from their files at every start (torch imported, a slower start); "
                        "make it writable or set XDG_CACHE_HOME")
        return False


def load_graph(model: str | Path, kind: str, params: dict, build: Callable[[], tuple[bytes, dict]],
               open_session: Callable[[bytes], Any], problem: Callable[[Any, dict], str | None],
               source: str) -> tuple[Any, dict, str]:
    """(session, info, how) of the model file ``model`` exported as ``kind`` with ``params``: from the cache where
    its entry verifies (``how`` ``cached``), else built (``build()`` -> (graph bytes, info), torch), cached and
    opened (``how`` ``exported``; ``rebuilt`` where an entry did not verify, said in a warning naming it).
    ``open_session(graph)`` opens a graph (ConfigError where it cannot); ``problem(session, info)`` says what is
    wrong with an opened graph's inputs (None: nothing). ``source`` names the model in errors."""
    model = Path(model)
    key = GraphKey(kind, file_sha256(model), params)
    paths = entry_paths(key)
    graph, info, why = read_entry(key, paths)
    if graph is not None:
        try:
            session = open_session(graph)
        except ConfigError as e:
            why = f"ONNX Runtime cannot load it ({e.message})"
        else:
            why = problem(session, info)
            if why is None:
                return session, info, "cached"
    if why is not None:
        log.warning(f"{source}: the cached ONNX graph {paths.onnx} does not verify ({why}): rebuilt from {model}")
    graph, info = build()
    write_entry(key, paths, model, graph, info)
    session = open_session(graph)
    bad = problem(session, info)
    if bad is not None:
        raise ConfigError(source, None, f"the ONNX graph exported from it does not fit: {bad}")
    return session, info, "exported" if why is None else "rebuilt"


def detector_params(imgsz: tuple[int, int] | None, opset: int) -> dict:
    """The export parameters of a detector's entry: input size (W, H; None: the checkpoint's own) and opset."""
    return {"imgsz": [int(imgsz[0]), int(imgsz[1])] if imgsz else None, "opset": int(opset)}


def detector_problem(session, info: dict) -> str | None:
    """What is wrong with a detector entry: an input other than (1, 3, H, W) of its ``imgsz``, or no class names."""
    size, names = info.get("imgsz"), info.get("class_names")
    if not (isinstance(names, list) and names and isinstance(size, list) and len(size) == 2):
        return "its description lacks class names or input size"
    try:
        ModelConfig.from_dict(dict(info.get("arch") or {}))
    except (TypeError, ValueError) as e:
        return f"its description's architecture is not valid ({e})"
    shape = list(session.get_inputs()[0].shape)
    want = [1, 3, int(size[1]), int(size[0])]
    return None if shape == want else f"its input is {shape}, expected {want}"


@dataclass(frozen=True)
class ModelInfo:
    """What a :class:`~.detector.Detector` knows of the checkpoint it was built from when its graph came from the
    cache (no weights: they are in the graph): the architecture, class names, input size (W, H) and the file."""

    cfg: ModelConfig
    class_names: list[str]
    imgsz: tuple[int, int]
    path: str

    @classmethod
    def from_info(cls, info: dict, path: str) -> "ModelInfo":
        try:
            cfg = ModelConfig.from_dict(dict(info["arch"]))
        except (KeyError, TypeError, ValueError) as e:
            raise ConfigError(path, "arch", f"cached description: {e}") from None
        size = info["imgsz"]
        return cls(cfg, [str(n) for n in info["class_names"]], (int(size[0]), int(size[1])), path)
