"""Detector network, decode, NMS and task-aligned assignment on hand-built tensors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from cone_perception.model import MODEL_SIZES, ConeYOLO, ModelConfig, model_config, model_names
from cone_perception.model.checkpoint import load_matching
from cone_perception.model.assign import TaskAlignedAssigner
from cone_perception.model.decode import decode_outputs, make_anchors, postprocess
from cone_perception.model.loss import DetectionLoss


@pytest.mark.parametrize("size", sorted(MODEL_SIZES))
def test_output_layout_any_multiple_of_32(size):
    m = ConeYOLO(model_config(size)).eval()
    for w, h in ((960, 288), (320, 96)):
        with torch.no_grad():
            y = m(torch.rand(1, 3, h, w))
        n_cells = sum((w // s) * (h // s) for s in m.strides)
        assert y.shape == (1, 4 + 5, n_cells)
        assert float(y[:, 4:].min()) >= 0 and float(y[:, 4:].max()) <= 1


def test_strides_of_the_sizes():
    assert model_config("p").strides == (8, 16, 32)
    assert model_config("p2").strides == (4, 8, 16, 32)
    # 7650 cells at 960x96 = 240x24 + 120x12 + 60x6 + 30x3: the stride-4 level comes first
    with torch.no_grad():
        assert ConeYOLO(model_config("p2")).eval()(torch.rand(1, 3, 96, 960)).shape == (1, 9, 7650)


def test_bad_strides_and_p2_on_a_pretrained_backbone_refused():
    d = model_config("p").to_dict()
    with pytest.raises(ValueError, match="strides must be"):
        ModelConfig.from_dict({**d, "strides": [4, 8, 16]})
    with pytest.raises(ValueError, match="stride-4 level needs the csp backbone"):
        ModelConfig.from_dict({**d, "strides": [4, 8, 16, 32], "backbone": "mobilenet_v2"})
    with pytest.raises(KeyError, match="unknown neck size"):
        model_config("mobilenet_v2-p2")
    assert "mobilenet_v2-p2" not in model_names() and "p2" in model_names()


def test_p2_warm_started_from_p_keeps_the_p_levels_exactly():
    """The stride-4 level is a side branch: with p's weights loaded, levels 8/16/32 are p's outputs."""
    torch.manual_seed(1)
    p = ConeYOLO(model_config("p")).eval()
    for mod in p.modules():  # non-trivial BN statistics, so a mismatch would show
        if isinstance(mod, torch.nn.BatchNorm2d):
            mod.running_mean.uniform_(-0.5, 0.5)
            mod.running_var.uniform_(0.5, 2.0)
    p2 = ConeYOLO(model_config("p2")).eval()
    loaded, fresh = load_matching(p2, p.state_dict())
    assert loaded == len(p.state_dict())
    assert fresh and all(k.startswith(("neck.td2.", "head.reg_p2.", "head.cls_p2.")) for k in fresh)
    x = torch.rand(1, 3, 64, 128)
    with torch.no_grad():
        ref, got = p.forward_raw(x), p2.forward_raw(x)
    assert len(got) == 4 and got[0].shape[2:] == (16, 32)
    for a, b in zip(ref, got[1:]):
        assert torch.equal(a, b)
    assert p2.num_params() - p.num_params() < 0.02 * p.num_params()  # the branch is light


def test_named_sizes_p_smaller_than_n():
    n, p = (ConeYOLO(model_config(s)) for s in ("n", "p"))
    assert model_config("n").channels == (16, 32, 64, 128, 256)  # YOLO11n widths
    assert p.num_params() < n.num_params() / 2


def test_fuse_matches_batchnorm_model():
    torch.manual_seed(0)
    m = ConeYOLO(model_config("p"))
    for mod in m.modules():
        if isinstance(mod, torch.nn.BatchNorm2d):
            mod.running_mean.uniform_(-0.5, 0.5)
            mod.running_var.uniform_(0.5, 2.0)
            mod.weight.data.uniform_(0.5, 1.5)
            mod.bias.data.uniform_(-0.2, 0.2)
    m.eval()
    x = torch.rand(1, 3, 64, 96)
    with torch.no_grad():
        ref = m(x)
        m.fuse()
        got = m(x)
    assert not any(isinstance(mod, torch.nn.BatchNorm2d) for mod in m.modules())
    assert torch.allclose(ref, got, atol=1e-3, rtol=1e-4)


def test_config_round_trip_and_bad_keys():
    cfg = model_config("p")
    assert ModelConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="unknown architecture keys"):
        ModelConfig.from_dict({**cfg.to_dict(), "wings": 2})
    with pytest.raises(KeyError, match="known"):
        model_config("xxl")


def test_decode_peaked_distribution_gives_known_box():
    reg_max, nc = 8, 5
    # one level of stride 8, 4x4 cells (input 32x32); others empty-sized levels are not needed here
    f = torch.full((1, 4 * reg_max + nc, 4, 4), -20.0)
    dist = [1, 2, 3, 4]  # l, t, r, b in stride units at cell (x=2, y=1)
    for side, d in enumerate(dist):
        f[0, side * reg_max + d, 1, 2] = 20.0
    f[0, 4 * reg_max + 3, 1, 2] = 5.0  # class 3 logit
    out = decode_outputs([f], (8,), reg_max, nc)
    k = 1 * 4 + 2
    cx_cell, cy_cell = 2.5, 1.5
    x1, y1, x2, y2 = (cx_cell - 1) * 8, (cy_cell - 2) * 8, (cx_cell + 3) * 8, (cy_cell + 4) * 8
    np.testing.assert_allclose(out[0, :4, k].numpy(), [(x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1], atol=1e-3)
    assert out[0, 4 + 3, k] == pytest.approx(1 / (1 + np.exp(-5.0)), abs=1e-6)


def _pred(boxes_xyxy, scores, classes, nc=5):
    b = np.asarray(boxes_xyxy, np.float32)
    out = np.zeros((4 + nc, len(b)), np.float32)
    out[0], out[1] = (b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2
    out[2], out[3] = b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]
    for i, (s, c) in enumerate(zip(scores, classes)):
        out[4 + c, i] = s
    return out


def test_nms_is_class_aware_and_filters():
    boxes = [[10, 10, 50, 90], [12, 11, 52, 92], [11, 10, 51, 90], [200, 10, 240, 90], [300, 10, 320, 40]]
    scores = [0.9, 0.8, 0.7, 0.6, 0.1]
    classes = [0, 0, 1, 2, 0]
    b, s, c = postprocess(_pred(boxes, scores, classes), conf=0.25, iou=0.5)
    # box 1 overlaps box 0 (same class) -> suppressed; box 2 overlaps but is another class -> kept;
    # box 4 is below the confidence threshold
    assert c.tolist() == [0, 1, 2]
    np.testing.assert_allclose(s, [0.9, 0.7, 0.6], atol=1e-6)
    np.testing.assert_allclose(b[0], boxes[0], atol=1e-4)
    b, s, c = postprocess(_pred(boxes, scores, classes), conf=0.25, iou=0.5, max_det=2)
    assert len(s) == 2 and s[0] == pytest.approx(0.9)
    b, s, c = postprocess(_pred(boxes, scores, classes), conf=0.95)
    assert b.shape == (0, 4) and s.shape == (0,)
    with pytest.raises(ValueError):
        postprocess(np.zeros((3, 10), np.float32))


def test_assigner_positives_inside_box_with_class_and_tiny_box_gets_cells():
    feats = [torch.zeros(1, 1, 12, 20), torch.zeros(1, 1, 6, 10), torch.zeros(1, 1, 3, 5)]
    anchors, strides = make_anchors(feats, (8, 16, 32))
    anchors_px = anchors * strides
    n = anchors.shape[0]
    gt = torch.tensor([[[40.0, 20.0, 72.0, 80.0], [120.0, 50.0, 124.0, 55.0]]])  # big, and a 4x5 px cone
    labels = torch.tensor([[[1], [3]]])
    mask = torch.ones(1, 2, 1)
    pd_boxes = gt[0, 0].expand(1, n, 4).clone()
    pd_boxes[0, :, :2] = anchors_px - 16
    pd_boxes[0, :, 2:] = anchors_px + 16
    pd_scores = torch.full((1, n, 5), 0.1)
    tl, tb, ts, fg = TaskAlignedAssigner(topk=10)(pd_scores, pd_boxes, anchors_px, labels, gt, mask)
    assert fg.sum() > 0
    pos = anchors_px[fg[0]]
    big = tl[0, fg[0]] == 1
    inside = (pos[big, 0] > 40) & (pos[big, 0] < 72) & (pos[big, 1] > 20) & (pos[big, 1] < 80)
    assert bool(inside.all()) and int(big.sum()) >= 1
    assert int((tl[0, fg[0]] == 3).sum()) >= 1  # the tiny cone still has a positive cell
    assert torch.all(ts[0, ~fg[0]] == 0)
    assert torch.all(ts[0, fg[0]].argmax(-1) == tl[0, fg[0]])


def test_loss_finite_with_and_without_targets_and_gradients_flow():
    torch.manual_seed(0)
    m = ConeYOLO(model_config("p")).train()
    crit = DetectionLoss(5, m.cfg.reg_max, m.strides)
    x = torch.rand(2, 3, 96, 160)
    t = torch.tensor([[0, 1, 10, 10, 30, 50], [0, 0, 50, 20, 60, 40], [1, 3, 100, 30, 104, 36]], dtype=torch.float32)
    loss, parts = crit(m(x), t)
    loss.backward()
    assert torch.isfinite(loss) and torch.all(parts > 0)
    assert m.head.cls[0][-1].weight.grad.abs().sum() > 0
    loss0, parts0 = crit(m(x), torch.zeros(0, 6))
    assert torch.isfinite(loss0) and parts0[0] == 0 and parts0[2] == 0 and parts0[1] > 0


def test_p2_loss_trains_the_stride4_level_on_tiny_boxes():
    torch.manual_seed(0)
    m = ConeYOLO(model_config("p2")).train()
    crit = DetectionLoss(5, m.cfg.reg_max, m.strides)
    t = torch.tensor([[0, 1, 40, 40, 44, 46], [0, 0, 100, 20, 103, 25]], dtype=torch.float32)  # 6 and 5 px tall
    loss, parts = crit(m(torch.rand(1, 3, 64, 160)), t)
    loss.backward()
    assert torch.isfinite(loss) and torch.all(parts > 0)
    assert m.head.reg_p2[-1].weight.grad.abs().sum() > 0 and m.neck.td2.cv1.conv.weight.grad.abs().sum() > 0
