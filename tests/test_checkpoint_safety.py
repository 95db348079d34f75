"""Checkpoints that cannot run code: weights_only loading, clear errors naming the file, finite weights."""

from __future__ import annotations

import os
import random
from pathlib import Path

import numpy as np
import pytest
import torch

from cone_perception.detector import Detector, default_model_path
from cone_perception.detector.verifier import DEFAULT_VERIFIER_NAME, load_verifier
from cone_perception.errors import ConfigError
from cone_perception.model import ConeYOLO
from cone_perception.model.checkpoint import FORMAT, VERSION, load_checkpoint, save_checkpoint
from cone_perception.model.config import model_config


@pytest.fixture(scope="module")
def tiny() -> ConeYOLO:
    torch.manual_seed(0)
    return ConeYOLO(model_config("n"))


class _Payload:
    """Unpickling this runs ``touch <path>``: what a crafted ``.pt`` would do with os.system."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return os.system, (f"touch {self.path}",)


def test_a_crafted_checkpoint_never_runs_its_code(tmp_path: Path, tiny: ConeYOLO) -> None:
    marker = tmp_path / "pwned"
    evil = tmp_path / "evil.pt"
    good = tmp_path / "good.pt"
    save_checkpoint(good, tiny, (320, 96))
    obj = torch.load(good, weights_only=True)
    obj["metrics"] = {"map50": _Payload(marker)}
    torch.save(obj, evil)
    torch.load(evil, weights_only=False)  # the payload is real: unsafe loading creates the file
    assert marker.exists()
    marker.unlink()
    for load in (load_checkpoint, Detector.load):
        with pytest.raises(ConfigError) as e:
            load(evil)
        assert str(evil) in str(e.value) and "refused" in str(e.value) and "system" in str(e.value)
        assert not marker.exists()


@pytest.mark.parametrize("content", [
    os.urandom(4096),
    b"",
    b"PK\x03\x04" + b"\0" * 100,  # a zip's first bytes, nothing after
])
def test_unreadable_files_name_the_file(tmp_path: Path, content: bytes) -> None:
    p = tmp_path / "bad.pt"
    p.write_bytes(content)
    with pytest.raises(ConfigError) as e:
        load_checkpoint(p)
    assert str(p) in str(e.value) and ("not a readable checkpoint" in str(e.value) or "refused" in str(e.value))


def test_a_truncated_checkpoint_names_the_file(tmp_path: Path) -> None:
    data = Path(default_model_path()).read_bytes()
    p = tmp_path / "cut.pt"
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(ConfigError, match="cut.pt"):
        load_checkpoint(p)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_weights_are_refused(tmp_path: Path, tiny: ConeYOLO, bad: float) -> None:
    p = tmp_path / "nan.pt"
    save_checkpoint(p, tiny, (320, 96))
    obj = torch.load(p, weights_only=True)
    key = next(k for k, v in obj["state_dict"].items() if v.is_floating_point() and v.numel() > 3)
    obj["state_dict"][key].view(-1)[3] = bad
    torch.save(obj, p)
    with pytest.raises(ConfigError) as e:
        load_checkpoint(p)
    assert str(p) in str(e.value) and key in str(e.value) and "NaN or inf" in str(e.value)


def test_what_todays_save_writes_still_loads(tmp_path: Path, tiny: ConeYOLO) -> None:
    """A ``last.pt`` as the trainer writes it (numpy RNG state, optimizer state, numpy numbers)."""
    opt = torch.optim.AdamW(tiny.parameters(), lr=1e-3)
    rng = {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}
    train = {"epoch": 3, "model": tiny.state_dict(), "optimizer": opt.state_dict(), "ema_updates": 7,
             "best_fitness": float("-inf"), "best_epoch": -1, "rng": rng, "config": {"imgsz": [320, 96]},
             "history": [{"epoch": 0, "loss": np.float64(1.5), "map50": np.float32(0.25), "n": np.int64(3)}]}
    metrics = {"map50": np.float64(0.5), "per_class": np.arange(5, dtype=np.float32), "name": "val"}
    p = tmp_path / "last.pt"
    save_checkpoint(p, tiny, (320, 96), data={"train": [{"images": 10}]}, metrics=metrics, train=train)
    ck = load_checkpoint(p)
    assert ck.train["rng"]["numpy"][0] == "MT19937"
    np.testing.assert_array_equal(ck.train["rng"]["numpy"][1], rng["numpy"][1])
    assert ck.train["history"][0]["loss"] == 1.5 and ck.metrics["map50"] == 0.5
    np.random.set_state(ck.train["rng"]["numpy"])  # usable as the trainer uses it
    random.setstate(ck.train["rng"]["python"])


def test_shipped_models_load_safely() -> None:
    for p in Path(default_model_path()).parent.glob("*.pt"):
        if p.name == DEFAULT_VERIFIER_NAME:  # the far strip's verifier: its own file kind, read weights-only
            assert load_verifier(str(p)).source == str(p)
            continue
        ck = load_checkpoint(p)
        assert ck.cfg is not None and FORMAT and VERSION
