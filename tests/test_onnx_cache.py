"""The ONNX cache (detector/onnx_cache.py, issue 43): a start on ONNX Runtime with the cache warm imports no torch;
an entry that does not verify (truncated, another model, another version, other inputs, unreadable) is rebuilt
with a warning and never run; a cache folder that cannot be written costs one warning, and the node runs as before.
Every test here has a cache folder of its own (``XDG_CACHE_HOME``)."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cone_perception.crop import SIDE
from cone_perception.detector import Detector, default_model_path, torch_backend
from cone_perception.detector import verifier as vf
from cone_perception.detector.onnx_cache import CACHE_FORMAT, onnx_cache_dir
from cone_perception.detector.verifier_net import probabilities, read_verifier

ROOT = Path(__file__).resolve().parents[1]
VERIFIER = ROOT / "models" / "cone_verifier.pt"


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    """A cache folder of this test's own (``XDG_CACHE_HOME``); returns the ONNX cache's folder in it."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return onnx_cache_dir()


def _entry(cache: Path, kind: str) -> tuple[Path, Path]:
    (graph,) = cache.glob(f"{kind}-*.onnx")
    return graph, graph.with_suffix(".json")


def _patches(n: int = 6) -> np.ndarray:
    return np.random.default_rng(3).integers(0, 255, (n, SIDE, SIDE, 3), dtype=np.uint8)


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_the_verifier_is_exported_once_then_read_from_the_cache_with_torchs_probabilities(cache, monkeypatch, caplog):
    with caplog.at_level(logging.WARNING):
        first = vf.load_verifier(str(VERIFIER))
    graph, desc = _entry(cache, "verifier")
    meta = json.loads(desc.read_text())
    assert meta["format"] == CACHE_FORMAT and meta["onnx_bytes"] == graph.stat().st_size
    assert meta["info"] == {"verify_below": 0.7, "min_p": 0.1, "min_px": 6.0, "max_px": 60.0}
    # the second load reads the cache: exporting again would fail
    monkeypatch.setattr(vf, "_torch", lambda: pytest.fail("the verifier was exported again"))
    second = vf.load_verifier(str(VERIFIER))
    assert _warnings(caplog) == []
    net, _ = read_verifier(VERIFIER, "test")
    want = probabilities(net, _patches())
    for v in (first, second):
        assert v.session is not None and v.net is None
        np.testing.assert_allclose(v.probabilities(np.zeros((200, 200, 3), np.uint8), np.zeros((0, 4))), [])
        x = _patches().transpose(0, 3, 1, 2).astype(np.float32) / 255
        got = 1 / (1 + np.exp(-v.session.run(None, {"x": x})[0]))
        np.testing.assert_allclose(got, want, atol=1e-5)


def _spoil_version(graph: Path, desc: Path) -> str:
    meta = json.loads(desc.read_text())
    desc.write_text(json.dumps({**meta, "package": "0.0.1"}))
    return "written by cone_perception 0.0.1"


def _spoil_model(graph: Path, desc: Path) -> str:
    meta = json.loads(desc.read_text())
    desc.write_text(json.dumps({**meta, "model_sha256": "0" * 64}))
    return "of another model"


def _truncate(graph: Path, desc: Path) -> str:
    graph.write_bytes(graph.read_bytes()[:1000])
    return "truncated or changed"


def _garbage(graph: Path, desc: Path) -> str:
    desc.write_bytes(b"\x00not json")
    return "description is unreadable"


def _foreign_graph(graph: Path, desc: Path) -> str:
    """Another graph under the entry's name, its description made to match its bytes: ONNX Runtime loads it, its
    input is not the verifier's."""
    Detector.load_for_band(default_model_path(), (320, 96))  # a detector's entry beside it
    (det,) = onnx_cache_dir().glob("detector-*.onnx")
    data = det.read_bytes()
    graph.write_bytes(data)
    meta = json.loads(desc.read_text())
    desc.write_text(json.dumps({**meta, "onnx_bytes": len(data), "onnx_sha256": hashlib.sha256(data).hexdigest()}))
    return "its input is images"


@pytest.mark.parametrize("spoil", [_spoil_version, _spoil_model, _truncate, _garbage, _foreign_graph])
def test_an_entry_that_does_not_verify_is_rebuilt_with_a_warning_never_run(cache, caplog, spoil):
    vf.load_verifier(str(VERIFIER))
    graph, desc = _entry(cache, "verifier")
    good = graph.read_bytes()
    why = spoil(graph, desc)
    with caplog.at_level(logging.WARNING):
        v = vf.load_verifier(str(VERIFIER))
    warned = _warnings(caplog)
    assert len(warned) == 1 and str(graph) in warned[0] and why in warned[0] and "rebuilt from" in warned[0], warned
    assert graph.read_bytes() == good and json.loads(desc.read_text())["package"] != "0.0.1"
    net, _ = read_verifier(VERIFIER, "test")
    x = _patches().transpose(0, 3, 1, 2).astype(np.float32) / 255
    np.testing.assert_allclose(1 / (1 + np.exp(-v.session.run(None, {"x": x})[0])), probabilities(net, _patches()),
                               atol=1e-5)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        vf.load_verifier(str(VERIFIER))
    assert _warnings(caplog) == []  # rebuilt entries verify


def test_a_changed_model_gets_an_entry_of_its_own(cache, tmp_path):
    vf.load_verifier(str(VERIFIER))
    import torch

    d = torch.load(VERIFIER, weights_only=True)
    changed = tmp_path / "changed.pt"
    torch.save({**d, "min_p": 0.2}, changed)
    assert vf.load_verifier(str(changed)).min_p == 0.2
    assert len(list(cache.glob("verifier-*.onnx"))) == 2
    assert vf.load_verifier(str(VERIFIER)).min_p == 0.1


def test_a_cache_folder_that_cannot_be_written_costs_one_warning_naming_it(tmp_path, monkeypatch, caplog):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    with caplog.at_level(logging.WARNING):
        a = vf.load_verifier(str(VERIFIER))
        b = vf.load_verifier(str(VERIFIER))
    warned = _warnings(caplog)
    assert len(warned) == 1 and str(blocker / "cone_perception" / "onnx") in warned[0], warned
    assert a.session is not None and b.session is not None  # runs from the model file as before the cache


def test_a_checkpoint_on_onnx_runtime_reads_names_size_and_architecture_from_the_cache(cache, monkeypatch):
    first = Detector.load_for_band(default_model_path(), (320, 96))
    with monkeypatch.context() as m:
        m.setattr(torch_backend, "checkpoint_graph", lambda *a: pytest.fail("exported again"))
        second = Detector.load_for_band(default_model_path(), (320, 96))
    assert second.backend == "onnx" and second.imgsz == first.imgsz == (320, 96)
    assert second.checkpoint.cfg == first.checkpoint.cfg and list(second.class_map) == list(first.class_map)
    assert second.describe() == first.describe()
    blob = np.random.default_rng(0).random((1, 3, 96, 320), dtype=np.float32)
    eager = Detector.load(default_model_path(), backend="torch", imgsz=(320, 96))
    np.testing.assert_allclose(second.raw(blob), eager.raw(blob), atol=1e-3)
    # another input size: another entry, built from the checkpoint
    assert Detector.load_for_band(default_model_path(), (352, 64)).imgsz == (352, 64)
    assert len(list(cache.glob("detector-*.onnx"))) == 2


def test_a_pipeline_node_started_on_a_warm_cache_imports_no_torch(cache):
    """The pipeline node with its defaults (band, far strip with the far model) and the opt-in verifier built in a fresh
    process after ``export --cache``: its detectors run on ONNX Runtime, and torch is not in ``sys.modules``."""
    from cone_perception.cli import main

    assert main(["export", "--cache"]) == 0
    assert len(list(cache.glob("*.onnx"))) == 2  # the band's and the strip's (the verifier is opt-in)
    assert main(["export", "--cache", "--param", "far_verifier:=auto"]) == 0
    assert len(list(cache.glob("*.onnx"))) == 3
    code = (
        "import sys, rclpy\n"
        "from rclpy.parameter import Parameter\n"
        "from cone_perception.nodes.pipeline import PipelineNode\n"
        "rclpy.init()\n"
        "node = PipelineNode(parameter_overrides=[Parameter('far_verifier', value='auto')])\n"
        "p = node.pipeline\n"
        "print(p.detector.backend, p.far.detector.backend, p.far.verifier.session is not None)\n"
        "print(sorted(m for m in sys.modules if m == 'torch' or m.startswith('torch.')))\n"
        "node.destroy_node()\n"
        "rclpy.shutdown()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT,
                         env=dict(os.environ))
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert lines[-2:] == ["onnx onnx True", "[]"], out.stdout + out.stderr[-2000:]
