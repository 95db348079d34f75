"""Image-attitude designs screened on the validation suite's cached drives (issue 41, part 3).

    .venv/bin/python docs/experiments/suite_attitude_designs.py BAG [BAG ...] [--set FIELD=VALUE,...] [--truth]
        [--attitude image|fused|imu|fixed] [--one-box NAME=VALUE,...] [--merge NAME=VALUE,...] [--fused NAME=VALUE,...]

Each BAG is a drive the suite rendered (`cone-perception validate --tuning --seconds 2 --cache DIR` leaves them in
DIR, named `tune-NAME`: screen on those, never on the judging drives). Each is replayed as the suite replays it
(`suite.run_drive`: the node's defaults) with the `ImageAttitudeConfig` fields given by `--set` changed (e.g.
`--set feet_cut_factor=0`, `--set min_height_px=12.0`, `--set process_sigma_deg=1.2,still_frames=0`), and one line
per drive plus the distribution (median / worst) of false cones per frame within 40 m, `/cones` recall 25-40 m and
the image attitude's median error at 7-15 m is printed.

`--one-box`: the keyword-only settings of `mapping.one_box_per_cone` changed (e.g. `--one-box part_inside=2.0`: the
rule that drops a part of a taller box's cone off); `--merge`: the keyword settings of `farband.merge_boxes` the
pipeline merges the band's and the strip's boxes with (e.g. `--merge max_band_px=1e9`: the far box wins whatever
the band box's size, as before issue 41's part 3).

`--truth`: also how many false cones per frame the same boxes give when mapped with the TRUE attitude
(`/attitude_gt`), with the true pitch and the fitted roll, and the other way round: how much of the false cones
is the attitude's (each box mapped on its own, as `ConeMapper.box_ranges` does, then matched as `replay` matches).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np

from cone_perception.attitude import Attitude, ImageAttitudeConfig
from cone_perception.data.bags import read_attitude_truth, read_ground_truth
from cone_perception.evaluation.localisation import match_cones
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.synth.writers import GT_TOPIC, bag_side_paths


def parse_set(text: str | None) -> dict:
    """``FIELD=VALUE,...`` -> {field: value} of ImageAttitudeConfig (values as Python literals)."""
    known = {f.name for f in fields(ImageAttitudeConfig)}
    out = {}
    for kv in filter(None, (text or "").split(",")):
        k, v = kv.split("=", 1)
        if k not in known:
            raise SystemExit(f"--set: {k} is no ImageAttitudeConfig field")
        out[k] = type(getattr(ImageAttitudeConfig(), k))(float(v) if "." in v or "e" in v else int(v))
    return out


def patch_config(changes: dict) -> None:
    """Every ImageAttitudeConfig made from now on takes ``changes`` (the pipeline makes its own)."""
    init = ImageAttitudeConfig.__init__

    def patched(self, *a, **k):
        init(self, *a, **k)
        for name, value in changes.items():
            setattr(self, name, value)
    ImageAttitudeConfig.__init__ = patched


def false_with(bag: Path, res, mode: tuple[str, str]) -> float:
    """False cones per frame within 40 m of the replay's boxes mapped one by one with (pitch, roll) taken from
    ``mode`` ("fit" or "true" each)."""
    calib = load_calibration(bag_side_paths(bag)[0])
    mapper, truth, att_true = ConeMapper(calib), read_ground_truth(bag, GT_TOPIC), read_attitude_truth(bag)
    false, frames = 0, 0
    for stamp in sorted(res.boxes):
        fit, true = res.attitude[stamp], att_true[stamp]
        pitch = fit.pitch_deg if mode[0] == "fit" else true[0]
        roll = fit.roll_deg if mode[1] == "fit" else true[1]
        att = Attitude(pitch, roll, 0.1, 0.1, "image", 0)
        boxes = res.boxes[stamp]
        cones = np.concatenate([mapper.map_boxes(boxes[k:k + 1], att) for k in range(len(boxes))]) if len(boxes) else []
        t = truth[stamp]
        if len(cones):
            pairs = match_cones(np.c_[cones["x"], cones["y"]], np.c_[t["x"], t["y"]])
            unmatched = np.ones(len(cones), bool)
            unmatched[[i for i, _, _ in pairs]] = False
            false += int((unmatched & (np.hypot(cones["x"], cones["y"]) <= 40.0)).sum())
        frames += 1
    return false / max(frames, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bags", nargs="+", type=Path)
    ap.add_argument("--set", default=None, help="ImageAttitudeConfig FIELD=VALUE,... (default: none changed)")
    ap.add_argument("--truth", action="store_true", help="also the false cones with the true attitude")
    ap.add_argument("--attitude", default="image", choices=("image", "fused", "imu", "fixed"),
                    help="the attitude the drives are replayed with (default image, the suite's)")
    ap.add_argument("--one-box", default=None, help="mapping.one_box_per_cone NAME=VALUE,... (keyword-only settings)")
    ap.add_argument("--merge", default=None, help="farband.merge_boxes NAME=VALUE,... (keyword settings)")
    ap.add_argument("--fused", default=None,
                    help="FusedAttitude NAME=VALUE,... (keyword-only settings; 'none' for None)")
    args = ap.parse_args()
    patch_config(parse_set(args.set))
    if args.fused:
        from cone_perception.attitude.fused import FusedAttitude
        kw = {k: (None if v == "none" else float(v)) for k, v in (kv.split("=", 1) for kv in args.fused.split(","))}
        unknown = set(kw) - set(FusedAttitude.__init__.__kwdefaults__ or {})
        if unknown:
            raise SystemExit(f"--fused: {sorted(unknown)} not among {sorted(FusedAttitude.__init__.__kwdefaults__)}")
        FusedAttitude.__init__.__kwdefaults__.update(kw)
    if args.merge:
        import functools

        from cone_perception import pipeline
        kw = {k: float(v) for k, v in (kv.split("=", 1) for kv in args.merge.split(","))}
        pipeline.merge_boxes = functools.partial(pipeline.merge_boxes, **kw)
    from cone_perception.mapping import one_box_per_cone
    for kv in filter(None, (args.one_box or "").split(",")):
        k, v = kv.split("=", 1)
        if k not in one_box_per_cone.__kwdefaults__:
            raise SystemExit(f"--one-box: {k} is none of {sorted(one_box_per_cone.__kwdefaults__)}")
        one_box_per_cone.__kwdefaults__[k] = float(v)
    from cone_perception.replay import suite  # after the patch: the pipeline builds its config then

    captured = {}
    offline = suite.offline_replay

    def keep(*a, **k):
        captured["res"] = offline(*a, **k)
        return captured["res"]
    suite.offline_replay = keep
    rows = []
    for bag in args.bags:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            r = suite.run_drive(bag, suite.Settings(attitude=args.attitude))
        rows.append(r)
        line = (f"{bag.name:28s} false {r['false_per_frame']:.2f} recall 15-25 {r['recall_15_25']:.3f} "
                f"25-40 {r['recall_25_40']:.3f} att 7-15 {r['err_att_7_15']:.3f} m (fixed H {r['err_fixed_7_15']:.3f}) "
                f"pitch error {r['pitch_err_deg'] or 0.0:.3f} deg")
        if args.truth:
            line += " | false, boxes one by one, pitch/roll " + " ".join(
                f"{p}/{q} {false_with(bag, captured['res'], (p, q)):.2f}" for p, q in
                (("fit", "fit"), ("true", "true"), ("true", "fit"), ("fit", "true")))
        print(line, flush=True)
    f, rc, a = (np.array([r[k] for r in rows], float) for k in ("false_per_frame", "recall_25_40", "err_att_7_15"))
    print(f"{args.set or 'defaults'}{' one-box ' + args.one_box if args.one_box else ''}{' merge ' + args.merge if args.merge else ''}{' fused ' + args.fused if args.fused else ''}: false/frame median {np.median(f):.2f} worst {f.max():.2f} (mean {f.mean():.2f}); "
          f"recall 25-40 median {np.median(rc):.3f} worst {rc.min():.3f}; att 7-15 median {np.median(a):.3f} "
          f"worst {a.max():.3f} m ({len(rows)} drives)")


if __name__ == "__main__":
    sys.exit(main())
