"""Where the raw /cones error 7-15 m of a synthetic drive comes from (issue 16, the 0.7x target).

Per drive NAME (run from the folder that holds them): the bag of `cone-perception synth bag`
(NAME, NAME_gt.jsonl, NAME_calib.yaml) and its replay (NAME_out with /cones), e.g.

    cone-perception synth bag --seconds 30 --fps 20 --seed 111 --no-jitter --out tune111
    cone-perception replay tune111 --calib tune111_calib.yaml --attitude fixed --out tune111_out
    .venv/bin/python docs/experiments/tracking_error_decomposition.py tune111 [...]

Printed, over the cones the frames show within 20 m (each detection matched to its true cone):
per range group the median error and the median radial / tangential error (the mapping's bias),
of /cones and of the rendered (exact, whole-pixel) boxes of gt.jsonl mapped the same way; per cone
over the frames it is seen at 7-15 m, the median size of its slowly changing part (a quadratic in
range fitted per cone) and of the rest (frame to frame); and the best any fusion can do with the
raw detections: the mean of a cone's last K detections (true motion, true association).
"""
import json, sys
import numpy as np
from cone_perception.data import bagio
from cone_perception.geometry.calib import load_calibration
from cone_perception.evaluation import match_cones
from cone_perception.mapping import ConeMapper
from cone_perception.records import BOX_DTYPE, CONE_DTYPE, from_pointcloud2


def main(names: list[str]) -> None:
    seq = {}  # (drive, cone) -> rows: frame, range, radial/tangential error of /cones, of the exact box, world error x/y
    for name in names:
        mapper = ConeMapper(load_calibration(f"{name}_calib.yaml"))
        cones = {bagio.stamp_ns(m.msg.header): from_pointcloud2(m.msg, CONE_DTYPE) for m in bagio.read_messages(f"{name}_out", "/cones")}
        for k, line in enumerate(open(f"{name}_gt.jsonl")):
            d = json.loads(line)
            gts = [c for c in d["cones"] if c["distance_m"] < 20]
            if not gts:
                continue
            g = np.array([[c["x_m"], c["y_m"]] for c in gts])
            b = np.zeros(len(gts), BOX_DTYPE)
            b["u1"], b["v1"], b["u2"], b["v2"] = np.array([c["box"] for c in gts]).T
            b["class_id"], b["score"] = [c["class_id"] for c in gts], 1.0
            uv = mapper.foot_points(b)
            exact = mapper.foot_offsets(mapper.ground.map_pixels(uv)[0], b["class_id"])  # the rendered box, mapped
            c = cones[d["stamp_ns"]]
            p = np.c_[c["x"], c["y"]].astype(np.float64)
            yaw = np.radians(d["pose"]["yaw_deg"])
            R = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
            for i, j, _ in match_cones(p, g):
                r = np.hypot(*g[j])
                ur = g[j] / r
                ut = np.array([-ur[1], ur[0]])
                world = R @ g[j] + (d["pose"]["x_m"], d["pose"]["y_m"])
                e, eb = p[i] - g[j], exact[j] - g[j]
                seq.setdefault((name, *np.round(world / 0.05).astype(int)), []).append(
                    (k, r, e @ ur, e @ ut, eb @ ur, eb @ ut, *(R @ e)))
    rows = np.vstack([np.array(v) for v in seq.values()])
    print("range m | n | median error | median radial | median tangential (/cones); the same of the exact boxes")
    for lo, hi in ((0, 4), (4, 7), (7, 10), (10, 15), (15, 20)):
        q = (rows[:, 1] >= lo) & (rows[:, 1] < hi)
        print(f"{lo}-{hi} | {q.sum()} | {np.median(np.hypot(rows[q, 2], rows[q, 3])):.3f} | {np.median(rows[q, 2]):+.3f} | {np.median(rows[q, 3]):+.3f}"
              f" | exact boxes {np.median(np.hypot(rows[q, 4], rows[q, 5])):.3f} | {np.median(rows[q, 4]):+.3f} | {np.median(rows[q, 5]):+.3f}")
    for label, cols in (("/cones", [2, 3]), ("exact boxes", [4, 5])):
        slow, fast = [], []
        for v in seq.values():
            v = np.array(v)
            v = v[(v[:, 1] >= 7) & (v[:, 1] < 15)]
            if len(v) < 6:
                continue
            fit = np.column_stack([np.polyval(np.polyfit(v[:, 1], v[:, c], 2), v[:, 1]) for c in cols])
            slow.append(fit), fast.append(v[:, cols] - fit)
        S, F = np.vstack(slow), np.vstack(fast)
        print(f"7-15 m, {label}, per cone (>= 6 frames): median |slow part| (quadratic in range) {np.median(np.hypot(*S.T)):.3f} m, "
              f"median |frame-to-frame part| {np.median(np.hypot(*F.T)):.3f} m")
    res = {}
    for v in seq.values():  # best case of fusing: the mean of a cone's last K detections, true motion, true association
        v = np.array(v)
        for n in np.flatnonzero((v[:, 1] >= 7) & (v[:, 1] < 15)):
            for K in (1, 3, 5, 10, 1000):
                res.setdefault(K, []).append(np.hypot(*v[max(0, n + 1 - K): n + 1, 6:8].mean(axis=0)))
    for K, e in res.items():
        print(f"7-15 m: mean of the last {K if K < 1000 else 'all'} detections: median error {np.median(e):.4f} m = {np.median(e) / np.median(res[1]):.2f} x one detection")


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    main(sys.argv[1:])
