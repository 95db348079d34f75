"""``synth mapcheck``: the localisation error that remains with a perfect detector (exact boxes, exact calibration,
the class foot-point rule), by distance band."""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..mapping import ConeMapper
from ..records import boxes_from_arrays
from .config import SynthConfig
from .scene import random_pose


def mapping_check(cfg: SynthConfig, frames: int, max_range_m: float = 30.0, band_m: float = 10.0) -> list[dict]:
    """Map the exact boxes of fully visible cones through the exact calibration with the class foot-point rule.

    Returns per distance band ``{"lo_m", "hi_m", "n", "median_m", "p95_m", "max_m"}``: the error that
    remains with a perfect detector (foot-point rule, pixel grid, body jitter if on).
    """
    if frames <= 0:
        raise ConfigError("--frames", None, f"must be > 0, got {frames}")
    cfg.validate()
    mapper = ConeMapper(cfg.calibration())
    renderer = cfg.renderer()
    rng = np.random.default_rng(cfg.seed)
    err, dist = [], []
    for k in range(frames):
        if k % 10 == 0:
            track, look = cfg.track(k, rng), renderer.new_look(rng)
        _, truths = renderer.render(track, random_pose(track, rng, cfg.jitter), look, rng)
        full = [t for t in truths if t.visible_fraction >= 0.999 and t.distance_m <= max_range_m]
        for t in full:  # one box at a time: map_boxes drops boxes beyond range, keep the pairing exact
            c = mapper.map_boxes(boxes_from_arrays(np.array([t.box]), np.ones(1), np.array([t.class_id])))
            if len(c):
                err.append(float(np.hypot(c["x"][0] - t.x_m, c["y"][0] - t.y_m)))
                dist.append(t.distance_m)
    err_a, dist_a = np.array(err), np.array(dist)
    out = []
    for lo in np.arange(0.0, max_range_m, band_m):
        sel = (dist_a >= lo) & (dist_a < lo + band_m)
        e = err_a[sel]
        out.append(
            {"lo_m": float(lo), "hi_m": float(lo + band_m), "n": int(sel.sum()),
             "median_m": float(np.median(e)) if e.size else float("nan"),
             "p95_m": float(np.percentile(e, 95)) if e.size else float("nan"),
             "max_m": float(e.max()) if e.size else float("nan")}
        )
    return out
