"""/cones vs /cones/tracked with a per-frame camera attitude (fixed / image / fused), issue 16 follow-up.

Inputs per drive NAME (tuning seeds only): the bag NAME (its /imu, /odom), NAME_calib.yaml,
NAME_gt.jsonl and NAME_out, the output of `replay NAME --attitude fixed --out NAME_out` (its
/cone_boxes: the detector's boxes, which do not depend on the attitude). Each attitude mode maps the
boxes again as `replay --attitude MODE` does (the IMU fed up to each frame's stamp), drops 0 % or
20 % of the detections (seed 0, as `replay --drop-detections`), tracks (motion from the cones, or
the bag's /odom with --odom; the tracker gets the frame's attitude as `replay --track` hands it, or
not with --independent; `--set attitude_common=true` switches the frame-common treatment on) and
scores with DriveEvaluation:

    .venv/bin/python docs/experiments/tracking_attitude.py [--odom] [--independent] [--set attitude_common=true] NAME [NAME ...]

One markdown row per drive, mode and drop share: median error 0-7 m and 7-15 m of /cones and
/cones/tracked (ratio tracked / raw), recall within 15 m of both, id switches per 100 frames.
``--set`` changes a TrackerConfig field (e.g. ``--set attitude_tau_s=1``).
"""
import argparse
import numpy as np
from cone_perception.data import bagio
from cone_perception.attitude import ImuAttitude, attitude_estimator, attitude_for_boxes
from cone_perception.geometry.calib import load_calibration
from cone_perception.mapping import ConeMapper
from cone_perception.records import BOX_DTYPE, from_pointcloud2
from cone_perception.data.bags import read_imu
from cone_perception.evaluation.tracking import DriveEvaluation, load_drive_truth
from cone_perception.replay import drop_detections
from cone_perception.data.bags import read_twists
from cone_perception.tracking import TrackerConfig, TrackingStage


def mapped(name: str, mode: str):
    """[(stamp, cones, attitude)] of drive ``name`` mapped with attitude ``mode``."""
    calib = load_calibration(f"{name}_calib.yaml")
    mapper = ConeMapper(calib)
    imu_msgs = read_imu(name) if mode in ("imu", "fused") else []
    imu = ImuAttitude() if imu_msgs else None
    _, est = attitude_estimator(mapper, mode, imu)
    out, k = [], 0
    for m in bagio.read_messages(f"{name}_out", "/cone_boxes"):
        stamp = bagio.stamp_ns(m.msg.header)
        while k < len(imu_msgs) and imu_msgs[k][0] <= stamp:
            imu.add(*imu_msgs[k])
            k += 1
        boxes = from_pointcloud2(m.msg, BOX_DTYPE)
        att = attitude_for_boxes(est, boxes, stamp)
        out.append((stamp, mapper.map_boxes(boxes, att), att))
    return calib, out


def run(name, calib, frames, drop, odom, kw, independent=False):
    truth = load_drive_truth(f"{name}_gt.jsonl")
    stage, ev, rng = TrackingStage(calib, TrackerConfig(**kw)), DriveEvaluation(truth), np.random.default_rng(0)
    twists, k = (read_twists(name, "/odom") if odom else []), 0
    for stamp, cones, att in frames:
        while k < len(twists) and twists[k][0] <= stamp:
            stage.add_twist(*twists[k])
            k += 1
        cones = drop_detections(cones, drop, rng)
        ev.add_raw(stamp, cones)
        tracked = stage.process(stamp, cones, None if independent else att)[0]
        ev.add_tracked(stamp, tracked)
    s = ev.summary()
    s["raw"]["groups"] = {g: v["median_err_m"] for g, v in ev.raw.summary()["groups"].items()}
    return s, dict(stage.events)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="+")
    ap.add_argument("--odom", action="store_true", help="motion from the bag's /odom")
    ap.add_argument("--modes", default="fixed,image,fused")
    ap.add_argument("--drops", default="0,0.2")
    ap.add_argument("--set", action="append", default=[], help="TrackerConfig field KEY=VALUE")
    ap.add_argument("--independent", action="store_true",
                    help="do not hand the tracker the attitude (each cone's covariance taken as independent: before the fix)")
    a = ap.parse_args()
    kw = {}
    for s in a.set:
        k, v = s.split("=", 1)
        kw[k] = {"true": True, "false": False}.get(v.lower(), None) if v.lower() in ("true", "false") else float(v)
    print("| drive | attitude | drop | 0-4 m /cones / tracked (ratio) | 4-7 m | 7-15 m | recall /cones | recall tracked | false/frame tracked | id sw./100 |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in a.names:
        for mode in a.modes.split(","):
            calib, frames = mapped(name, mode)
            for drop in (float(d) for d in a.drops.split(",")):
                s, ev = run(name, calib, frames, drop, a.odom, kw, a.independent)
                r, t = s["raw"], s["tracked"]
                cells = []
                for g in ("near 0-4 m", "mid 4-7 m", "far 7-15 m"):
                    ra, tb = r["groups"][g], t["groups"][g]["median_err_m"]
                    cells.append(f"{ra:.3f} / {tb:.3f} ({tb / ra:.2f})")
                print(f"| {name.rsplit('/', 1)[-1]} | {mode} | {drop:.0%} | " + " | ".join(cells) + f" | {r['recall']:.3f} | "
                      f"{t['recall']:.3f} | {t['false_per_frame']:.2f} | {t['id_switches_per_100_frames']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
