"""The image attitude with the far model in the strip and the real frames' box behaviour (issue 27's remaining rendered
target, 7-15 m <= 0.12 m image only, jitter on): designs for how the fit reads the far model's boxes, on tuning drives.

Each drive's boxes come from the cache of ``far_box_model.py`` (``--cache DIR``: the band through its model, halved,
and the calibration's strip at full resolution through the far model and through the band's model, attitude fixed so
the strip stays at the calibration's rows). As ``replay --box-behaviour real`` does, the band's boxes are given the
band model's real behaviour (``synth/boxlook.py``, seed 0) and the strip's boxes their network's (the far model's
sidecar, or the band model's for the band's model in the strip; seed 1), per drive; then merged as the pipeline merges
them (``merge_boxes``, ``one_box_per_cone``, ``drawn_by_far``) and each design re-runs the image attitude (image
mode, each network's boxes through its own box model, sizes over frames) and the mapping; scored as ``replay
--gt-topic`` scores (median error of matched cones 7-15 m and 15-25 m, median |pitch| error against /attitude_gt).

    .venv/bin/python docs/experiments/far_box_model.py --cache /tmp/26f /tmp/a27/tune/djit104 /tmp/a27/tune/djit105 /tmp/a27/tune/djit106
    .venv/bin/python docs/experiments/attitude_far_real.py --cache /tmp/26f /tmp/a27/tune/djit10[456] [--designs 0,1,2]

The strip is not moved with the attitude here (the replays move it with the previous frame's), so a design's effect
on which far boxes the next frames get is not in these figures: confirm on the held-out drives with ``replay``.
"""
import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from far_box_model import record  # noqa: E402

from cone_perception.attitude import ImageAttitudeConfig, attitude_for_boxes  # noqa: E402
from cone_perception.attitude.box_files import read_box_model  # noqa: E402
from cone_perception.attitude.boxes import FAR_MODEL_TOP_BIAS_EXTRA_PX, BoxReading  # noqa: E402
from cone_perception.detector.farband import drawn_by_far, merge_boxes  # noqa: E402
from cone_perception.evaluation import LocalisationReport  # noqa: E402
from cone_perception.geometry.calib import load_calibration  # noqa: E402
from cone_perception.mapping import ConeMapper, one_box_per_cone  # noqa: E402
from cone_perception.resources import default_far_model_path, default_model_path  # noqa: E402
from cone_perception.synth.boxlook import BoxBehaviour  # noqa: E402

# (name, strip source, ImageAttitudeConfig changes, far reading changes (BoxReading fields), how the fit is fed)
DESIGNS = [
    ("no strip (band alone)", None, {}, {}, "merged"),
    ("band's model in the strip", "strip_band", {}, {}, "merged"),
    ("far model in the strip (shipped)", "strip_far", {}, {}, "merged"),
    ("far boxes left out of the fit", "strip_far", {}, {}, "no_far"),
    ("the band's own boxes to the fit where it saw the cone, far boxes only for the rest", "strip_far", {}, {}, "band_first"),
    ("far boxes' tops: spread not averaged (persistent sigma = sidecar spread)", "strip_far", {}, {"persist_rel": 1.0}, "merged"),
    ("far boxes' tops: half the spread persistent", "strip_far", {}, {"persist_rel": 0.5}, "merged"),
    ("far boxes' tops: twice the spread persistent", "strip_far", {}, {"persist_rel": 2.0}, "merged"),
    ("diagnostic: far boxes read with their sidecar AND the far model's rendered table", "strip_far", {}, {"table_too": True}, "merged"),
    ("band's model in the strip, band's boxes first", "strip_band", {}, {}, "band_first"),
    ("far boxes left out, band's boxes first", "strip_far", {}, {}, "band_only_of_merge"),
    ("far boxes checked against the band's boxes of the same cones (running medians of their offsets taken off)",
     "strip_far", {}, {}, "cross"),
    ("the same, pairs only where the band's box is >= 24 px (12 px at its input)", "strip_far", {}, {}, "cross:24"),
    ("far boxes' tops checked against the band's (bottoms left)", "strip_far", {}, {}, "crosstop"),
]


def frames_for(d: dict, source: str | None, bm_band, bm_far, seed: int, look_table: bool = False) -> list:
    """Per frame: (stamp, merged records, far mask, band records given the behaviour); ``look_table``: the far model's
    boxes have its rendered offset taken out before the real behaviour is given (``BoxBehaviour(rendered_table=)``, as
    ``replay --box-behaviour real`` does now; off: as it did before)."""
    if bm_band is None:  # boxes as rendered
        look_band = look_strip = lambda r: r  # noqa: E731
    else:
        table = FAR_MODEL_TOP_BIAS_EXTRA_PX if look_table and source == "strip_far" else ()
        look_band = BoxBehaviour(bm_band, seed=seed)
        look_strip = BoxBehaviour(bm_far if source == "strip_far" else bm_band, seed=seed + 1, rendered_table=table)
    out = []
    for f in d["frames"]:
        band = look_band(f["band"])
        if source is None:
            out.append((f["stamp"], one_box_per_cone(band), None, band))
            continue
        strip = look_strip(f[source])
        merged = one_box_per_cone(merge_boxes(band, strip))
        out.append((f["stamp"], merged, drawn_by_far(merged, strip), band))
    return out


def fit_input(kind: str, merged, far, band):
    """The records and far mask the attitude reads, for one way of feeding it."""
    if far is None or kind == "merged":
        return merged, far
    if kind == "no_far":
        return merged[~far], np.zeros(int((~far).sum()), bool)
    # band_first: the band's boxes (after the same dedup) for cones it saw; far boxes only for cones the band missed
    from cone_perception.detector.farband import same_cone

    fb = merged[far]
    b = one_box_per_cone(band)
    seen = same_cone(b, fb, True).any(0) if len(b) and len(fb) else np.zeros(len(fb), bool)
    if kind == "band_only_of_merge":
        return b, np.zeros(len(b), bool)
    recs = np.concatenate([b, fb[~seen]])
    return recs, np.concatenate([np.zeros(len(b), bool), np.ones(int((~seen).sum()), bool)])


def patch(persist_rel: float, table_too: bool, far_sigma: float):
    """Prototype hooks (not the shipped fit): far boxes' persistent top sigma, the far table beside the sidecar."""
    from cone_perception.attitude import image as image_mod

    orig_read, orig_avg = image_mod.ImageAttitude._read, image_mod.ImageAttitude._average_sizes

    def _read(self, boxes, far):
        out, extra, rel, scatter = orig_read(self, boxes, far)
        if table_too and far is not None:
            from cone_perception.attitude.boxes import box_top_extra_px

            f = np.asarray(far, bool)
            extra[f] += box_top_extra_px(boxes[f, 3] - boxes[f, 1], FAR_MODEL_TOP_BIAS_EXTRA_PX)
        return out, extra, rel, scatter

    def _average_sizes(self, sizes, theta, rays, v_top, cls, rel, cov):
        v, s = orig_avg(self, sizes, theta, rays, v_top, cls, rel, cov)
        if persist_rel > 0:
            f = np.isclose(np.asarray(rel, float) * np.ones(len(v)), far_sigma)
            v_foot = self.K[1, 1] * rays[:, 1] / rays[:, 2] + self.K[1, 2]
            h = np.maximum(v_foot - v, 1e-3)
            s = np.where(f, np.sqrt(s**2 + (persist_rel * far_sigma * h) ** 2), s)
        return v, s

    image_mod.ImageAttitude._read, image_mod.ImageAttitude._average_sizes = _read, _average_sizes
    return lambda: (setattr(image_mod.ImageAttitude, "_read", orig_read),
                    setattr(image_mod.ImageAttitude, "_average_sizes", orig_avg))


class CrossCheck:
    """Prototype: the far network's boxes checked against the band's boxes of the same cones (both read through their own
    box models): the running medians of the far boxes' top and bottom offsets from the band's (fractions of the height),
    taken off the far boxes the fit reads once ``min_pairs`` pairs are in."""

    def __init__(self, bm_band, bm_far, min_pairs: int = 30, keep: int = 3000, min_band_px: float = 0.0,
                 tops_only: bool = False):
        self.tops_only = tops_only
        self.bm_band, self.bm_far, self.min_pairs, self.keep = bm_band, bm_far, min_pairs, keep
        self.min_band_px = min_band_px  # pairs only where the band's box is at least this tall (full px)
        self.dt, self.db = [], []

    def __call__(self, recs, far, band):
        from cone_perception.detector.farband import same_cone

        fb = recs[far]
        if len(fb) and len(band):
            m = same_cone(band, fb, True) & ((band["v2"] - band["v1"]) >= self.min_band_px)[:, None]
            one = m.sum(0) == 1
            j = np.flatnonzero(one)
            i = np.argmax(m[:, one], axis=0)
            if len(j):
                bc = self.bm_band.correct(_xyxy(band[i]))
                fc = self.bm_far.correct(_xyxy(fb[j]))
                h = bc[:, 3] - bc[:, 1]
                self.dt = (self.dt + list((fc[:, 1] - bc[:, 1]) / h))[-self.keep:]
                self.db = (self.db + list((fc[:, 3] - bc[:, 3]) / h))[-self.keep:]
        if len(self.dt) < self.min_pairs or not far.any():
            return recs
        out = recs.copy()
        hc = self.bm_far.correct(_xyxy(recs[far]))
        hc = hc[:, 3] - hc[:, 1]
        out["v1"][far] = recs["v1"][far] - np.median(self.dt) * hc
        if not self.tops_only:
            out["v2"][far] = recs["v2"][far] - np.median(self.db) * hc
        return out


def _xyxy(r):
    return np.column_stack([r["u1"], r["v1"], r["u2"], r["v2"]]).astype(np.float64)


def run_drive(bag: str, d: dict, frames: list, config, kind: str) -> tuple:
    m = ConeMapper(load_calibration(bag + "_calib.yaml"))
    est = m.image_attitude(config)
    rep, ep = LocalisationReport(max_range_m=m.calib.max_range_m), []
    cross = (CrossCheck(config.box_model, config.far_reading.box_model if config.far_reading else None,
                        min_band_px=float(kind.split(":")[1]) if ":" in kind else 0.0, tops_only="top" in kind)
             if kind.startswith("cross") else None)
    for st, merged, far, band in frames:
        recs, fmask = fit_input("merged" if cross else kind, merged, far, band)
        if cross is not None and far is not None:
            recs = cross(recs, fmask, band)
        a = attitude_for_boxes(est, recs, st, fmask)
        rep.add_frame(m.map_boxes(merged, a), d["truth"][st])
        ep.append(abs(a.pitch_deg - d["att"][st][0]))
    s = rep.summary()
    return (s["groups"]["far 7-15 m"]["median_err_m"], s["extra_groups"]["15-25 m"]["median_err_m"], float(np.median(ep)),
            est.counts.calibration)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bags", nargs="+")
    ap.add_argument("--cache", required=True, type=Path, help="far_box_model.py's cache folder")
    ap.add_argument("--designs", default="", help="comma-separated design numbers (default all)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="an ImageAttitudeConfig field (sizes.FIELD: a SizeTrackConfig field) for every design")
    ap.add_argument("--as-rendered", action="store_true", help="boxes as rendered, read through the rendered tables "
                    "(issue 26's case)")
    ap.add_argument("--look-table", action="store_true", help="the far model's rendered offset (its rendered table) taken "
                    "out of its boxes before they are given the real behaviour")
    ap.add_argument("--far-look-box-model", default=None, help="a sidecar to GIVE the far model's boxes their behaviour "
                    "with, the fit still reading them through --far-box-model's (a wrong sidecar: robustness)")
    ap.add_argument("--far-box-model", default=None, help="the far model's sidecar to give and read its boxes with "
                    "(default: the shipped model's)")
    args = ap.parse_args()
    bags = [b.rstrip("/") for b in args.bags]
    bm_band = read_box_model(default_model_path())
    far_path = Path(args.far_box_model) if args.far_box_model else default_far_model_path()
    bm_far = read_box_model(far_path) if not args.far_box_model else _sidecar(far_path)
    bm_look = _sidecar(Path(args.far_look_box_model)) if args.far_look_box_model else bm_far
    data = {b: record(b, args.cache) for b in bags}
    pick = {int(x) for x in args.designs.split(",") if x}
    print(f"drives {', '.join(Path(b).name for b in bags)}; real boxes: band spread {bm_band.sigma_rel}, far spread {bm_far.sigma_rel}")
    print("| # | design | " + " | ".join(f"{Path(b).name} 7-15 / 15-25 m / pitch err" for b in bags) + " | mean 7-15 m | mean 15-25 m |")
    print("|---|---|" + "---|" * (len(bags) + 2))
    for k, (name, source, cfg, fr, kind) in enumerate(DESIGNS):
        if pick and k not in pick:
            continue
        fr = dict(fr)
        undo = patch(fr.pop("persist_rel", 0.0), fr.pop("table_too", False), bm_far.sigma_rel)
        try:
            far_reading = (BoxReading(None, FAR_MODEL_TOP_BIAS_EXTRA_PX, "far") if args.as_rendered else BoxReading(bm_far, (), "far")
                           ) if source == "strip_far" else None
            config = replace(ImageAttitudeConfig(box_model=None if args.as_rendered else bm_band, far_reading=far_reading), **cfg)
            for kv in args.set:
                key, val = kv.split("=")
                if key.startswith("sizes."):
                    config = replace(config, size_tracks=replace(config.size_tracks, **{key[6:]: float(val)}))
                else:
                    cur = getattr(config, key)
                    config = replace(config, **{key: float(val) if cur is None else type(cur)(float(val))})
            r = [run_drive(b, data[b], frames_for(data[b], source, None if args.as_rendered else bm_band, bm_look, 0, args.look_table), config, kind) for b in bags]
        finally:
            undo()
        print(f"| {k} | {name} | " + " | ".join(f"{a:.3f} / {b:.3f} / {c:.3f}" for a, b, c, _ in r)
              + f" | {np.mean([x[0] for x in r]):.3f} | {np.mean([x[1] for x in r]):.3f} |", flush=True)


def _sidecar(path: Path):
    import yaml

    from cone_perception.attitude.boxes import BoxModel

    return BoxModel.from_dict(yaml.safe_load(path.read_text())["box_model"], str(path))


if __name__ == "__main__":
    main()
