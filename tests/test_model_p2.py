"""The stride-4 output level (size ``p2``, issue 26): checkpoint round trip, warm start from a
3-level checkpoint (``train --init-from``), and the places that refuse a 4-level model."""

from __future__ import annotations

import pytest
import torch

from cone_perception.errors import ConfigError
from cone_perception.model import ConeYOLO, model_config
from cone_perception.model.checkpoint import load_checkpoint, save_checkpoint
from cone_perception.train.distill import check_teacher
from cone_perception.train.trainer import TrainConfig, build_model


def _p_checkpoint(path, seed=3):
    torch.manual_seed(seed)
    m = ConeYOLO(model_config("p"))
    with torch.no_grad():
        for v in m.parameters():
            v.add_(0.01 * torch.randn_like(v))
    save_checkpoint(path, m, (320, 96))
    return m


def test_p2_checkpoint_round_trip(tmp_path):
    torch.manual_seed(0)
    m = ConeYOLO(model_config("p2")).eval()
    save_checkpoint(tmp_path / "p2.pt", m, (960, 96))
    ck = load_checkpoint(tmp_path / "p2.pt")
    assert ck.cfg.strides == (4, 8, 16, 32) and ck.cfg.name == "p2" and ck.cfg.head_p2_ch == 16
    got = ck.build_model()
    x = torch.rand(1, 3, 96, 320)
    with torch.no_grad():
        assert torch.equal(m(x), got(x))


def test_old_checkpoints_without_head_p2_ch_still_load(tmp_path):
    """A 3-level checkpoint written before the field existed (its arch has no head_p2_ch) loads."""
    m = _p_checkpoint(tmp_path / "p.pt")
    obj = torch.load(tmp_path / "p.pt", weights_only=True)
    del obj["arch"]["head_p2_ch"]
    torch.save(obj, tmp_path / "old.pt")
    ck = load_checkpoint(tmp_path / "old.pt")
    assert ck.cfg.strides == (8, 16, 32)
    assert torch.equal(ck.state_dict["head.reg.0.2.weight"], m.state_dict()["head.reg.0.2.weight"])


def test_init_from_loads_every_matching_tensor(tmp_path, caplog):
    p = _p_checkpoint(tmp_path / "p.pt")
    cfg = TrainConfig(data="", out=str(tmp_path / "run"), model="p2", init_from=str(tmp_path / "p.pt"))
    with caplog.at_level("INFO"):
        m = build_model(cfg)
    assert m.cfg.strides == (4, 8, 16, 32)
    n_p = len(p.state_dict())
    assert f"{n_p} tensors loaded" in caplog.text
    for k, v in p.state_dict().items():
        assert torch.equal(m.state_dict()[k], v), k
    fresh = ConeYOLO(model_config("p2")).state_dict()
    assert m.state_dict()["head.reg_p2.2.bias"].shape == fresh["head.reg_p2.2.bias"].shape


def test_init_from_refused_where_it_cannot_work(tmp_path):
    _p_checkpoint(tmp_path / "p.pt")
    with pytest.raises(ConfigError, match="starts a named model"):
        build_model(TrainConfig(data="", out="x", model=str(tmp_path / "p.pt"), init_from=str(tmp_path / "p.pt")))
    with pytest.raises(ConfigError, match="not a warm start"):  # n's widths differ from p's: 62 of 366 fit
        build_model(TrainConfig(data="", out="x", model="n", init_from=str(tmp_path / "p.pt")))


def test_distillation_between_3_and_4_levels_refused():
    p, p2 = ConeYOLO(model_config("p")), ConeYOLO(model_config("p2"))
    with pytest.raises(ConfigError, match="strides"):
        check_teacher(p, p2, "teacher.pt")
    check_teacher(p2, p2, "teacher.pt")  # same strides: fine
