"""Designs for `attitude: fused` at 7-15 m (docs/benchmarks.md, "Fused attitude: designs"), on the
tuning drives of docs/experiments/attitude_designs.py (same bags, same cached boxes; never the held-out
seeds 301-303). Each design re-runs the attitude and the mapping over the cached boxes and is scored as
`replay --gt-topic` scores (median position error at 7-15 m, median |pitch| / |roll| error), with the
bag's /imu (--imu-rest 0,0). `fused` is as it was then, without the later ground gate (`gate=None`);
the image fit runs with today's defaults (its still test has changed since: 2 s at 1.3x).

    .venv/bin/python docs/experiments/attitude_fused_designs.py /tmp/att/jit1?? /tmp/att/car1??
    .venv/bin/python docs/experiments/attitude_fused_designs.py --series /tmp/att/jit1?? /tmp/att/car1??

``--series``: the attitude alone, without mapping (fast): per frame the fit (linearised at the truth),
the IMU and the truth, and the ground-offset filters on them (median |error| of pitch and roll per
kind: mean / worst drive). ``--imu-rate``: the same with the IMU's orientation first smoothed with its
angular rate (a Kalman filter: rate-integrated prediction, orientation noise 0.03 deg), the bag's /imu
read again for the rates, the kept roll bias state.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from attitude_designs import cached, print_design_table, run_drive  # noqa: E402

from cone_perception.attitude import Attitude, FusedAttitude, ImageAttitudeConfig, rpy_from_quaternion  # noqa: E402
from cone_perception.geometry.calib import load_calibration  # noqa: E402
from cone_perception.mapping import ConeMapper  # noqa: E402


class TwoState(FusedAttitude):
    """Tried: the ground offset per axis as (offset, rate) with white acceleration ``qa`` (deg/s^1.5)."""

    def __init__(self, image, imu, qa=(0.05, 0.03), s0=(1.2, 0.6), sr0=(0.5, 0.3)):
        super().__init__(image, imu, roll_bias_prior_frames=0.0, gate=None)
        self.qa, self.X = np.array(qa), np.zeros((2, 2))
        self.P2 = np.array([np.diag([s0[i] ** 2, sr0[i] ** 2]) for i in range(2)])
        self.image.cfg.bias_tau_frames = 1200.0

    def update(self, boxes, class_ids, stamp_ns):
        body = self.imu.at(stamp_ns)
        if body is None:
            return self.image.update(boxes, class_ids)
        dt, s_imu = 0.05, self.imu.sigma_deg
        F = np.array([[1.0, dt], [0.0, 1.0]])
        for i in range(2):
            self.X[i] = F @ self.X[i]
            self.P2[i] = F @ self.P2[i] @ F.T + self.qa[i] ** 2 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        res = self.image.fit(boxes, class_ids, body + self.X[:, 0] + self.image.bias)
        wm = 1.0
        if res is not None and np.all(np.abs(res[0]) <= self.image.cfg.max_abs_deg):
            z, Rz, _ = res
            wm = self.image.motion_weight(z, Rz)
            m = self.image.debias(z) - body
            for i in range(2):
                P = self.P2[i]
                K = P[:, 0] / (P[0, 0] + Rz[i, i] + s_imu**2)
                self.X[i] = self.X[i] + K * (m[i] - self.X[i, 0])
                self.P2[i] = P - np.outer(K, P[0])
        else:
            wm = self.image.motion_weight(None, None)
        att = (body + self.X[:, 0]) * wm
        return Attitude(float(att[0]), float(att[1]), 0.1, 0.1, "fused", 0)


class SlowOffset(FusedAttitude):
    """Tried: a second, slow ground offset per axis (random walk ``qs`` deg a frame, 0 = none), used while
    the fast one stays within ``blend[0]`` of it, blending to the fast one over ``blend[1]`` more."""

    def __init__(self, image, imu, qs=(0.003, 0.0), blend=(0.04, 0.02)):
        super().__init__(image, imu, gate=None)
        self.qs, self.blend = np.asarray(qs) ** 2, blend
        self.gs, self.Ps = np.zeros(2), np.full(2, 4.0)

    def update(self, boxes, class_ids, stamp_ns):
        body = self.imu.at(stamp_ns)
        if body is None:
            return self.image.update(boxes, class_ids)
        s_imu = self.imu.sigma_deg
        self.Pg = self.Pg + np.eye(2) * self.q
        res = self.image.fit(boxes, class_ids, body + self.g + np.array([0.0, self.roll_bias]))
        wm = None
        if res is not None and np.all(np.abs(res[0]) <= self.image.cfg.max_abs_deg):
            z, Rz, _ = res
            wm = self.image.motion_weight(z, Rz)
            z = z - self.debias_roll(float(z[1] - body[1]))
            G = self.Pg @ np.linalg.inv(self.Pg + Rz + np.eye(2) * s_imu**2)
            self.g = self.g + G @ (z - body - self.g)
            self.Pg = (np.eye(2) - G) @ self.Pg
            self.Ps = self.Ps + self.qs
            Gs = self.Ps / (self.Ps + np.diag(Rz) + s_imu**2)
            self.gs = self.gs + Gs * (z - body - self.gs)
            self.Ps = (1.0 - Gs) * self.Ps
        if wm is None:
            wm = self.image.motion_weight(None, None)
        d = self.g - self.gs
        w = np.where(self.qs > 0, np.clip((np.abs(d) - self.blend[0]) / self.blend[1], 0.0, 1.0), 1.0)
        att = (body + self.gs + w * d) * wm
        return Attitude(float(att[0]), float(att[1]), 0.1, 0.1, "fused", 0)


class Truth(FusedAttitude):
    """The bag's true attitude plus a fixed error (pitch, roll): what an attitude error costs at 7-15 m."""

    truth: dict = {}

    def __init__(self, image, imu, err=(0.0, 0.0)):
        super().__init__(image, imu, gate=None)
        self.err = np.array(err)

    def update(self, boxes, class_ids, stamp_ns):
        t = np.array(Truth.truth[stamp_ns]) + self.err
        return Attitude(float(t[0]), float(t[1]), 0.05, 0.05, "fused", 0)


DESIGNS = [
    ("truth (the floor: boxes only)", lambda e, i: Truth(e, i)),
    ("truth + 0.05 deg pitch", lambda e, i: Truth(e, i, (0.05, 0.0))),
    ("truth + 0.1 deg roll", lambda e, i: Truth(e, i, (0.0, 0.1))),
    ("truth + 0.2 deg roll", lambda e, i: Truth(e, i, (0.0, 0.2))),
    ("IMU alone", lambda e, i: FusedAttitude(e, i, use_image=False)),
    ("two-state offset, qa 0.05 / 0.03", lambda e, i: TwoState(e, i)),
    ("two-state offset, qa 0.5 / 0.3", lambda e, i: TwoState(e, i, qa=(0.5, 0.3))),
    ("two-state offset, qa 1.0 / 0.5", lambda e, i: TwoState(e, i, qa=(1.0, 0.5))),
    ("kept: roll bias against the IMU, prior 30", lambda e, i: FusedAttitude(e, i, gate=None)),
    ("roll bias against the IMU, prior 20", lambda e, i: FusedAttitude(e, i, roll_bias_prior_frames=20.0, gate=None)),
    ("roll bias against the IMU, prior 50", lambda e, i: FusedAttitude(e, i, roll_bias_prior_frames=50.0, gate=None)),
    ("kept + slow pitch offset (0.003, blend 0.04 / 0.02)", lambda e, i: SlowOffset(e, i)),
    ("kept + slow pitch and roll offset", lambda e, i: SlowOffset(e, i, qs=(0.003, 0.003))),
]


def _still_from(n: float):
    def make(e, i):
        e.cfg.still_min_frames = n
        return FusedAttitude(e, i, gate=None)
    return make


#: the start of a drive: the still test judges from this many fits (before: moving); run with flat bags too
STILL_DESIGNS = [(f"kept, still test from {n} fits", _still_from(n)) for n in (5.0, 3.0)]


def score(bag: str, d: dict, make) -> tuple[float, float, float]:
    Truth.truth = d["att"]
    return run_drive(bag, d, lambda m, imu: make(m.image_attitude(ImageAttitudeConfig()), imu), True)


def series(bag: str, d: dict) -> np.ndarray:
    """(n, 8): truth (pitch, roll), IMU, fit (NaN without), fit variance; degrees."""
    est = ConeMapper(load_calibration(bag + "_calib.yaml")).image_attitude(ImageAttitudeConfig())
    imu = {s: np.degrees(rpy_from_quaternion(*q))[[1, 0]] for s, q in d["imu"]}
    rows = []
    for st, rec in d["frames"]:
        b = np.column_stack([rec["u1"], rec["v1"], rec["u2"], rec["v2"]]).astype(float)
        t = np.array(d["att"][st])
        r = est.fit(b, rec["class_id"].astype(np.intp), t)
        z, R = (r[0], np.diag(r[1])) if r is not None else (np.full(2, np.nan), np.full(2, np.nan))
        rows.append(np.concatenate([t, imu[st], z, R]))
    return np.array(rows)


def offset_filter(a: np.ndarray, q=(0.05, 0.05), k=1.0, roll_bias_prior=None, ou_s=(0.0, 0.0),
                  slow=None, simu=0.1) -> np.ndarray:
    """Median |error| (pitch, roll) of IMU + a random-walk ground offset (``q`` deg a frame, fit variance
    times ``k``); ``roll_bias_prior``: None = the image bias state (mean of the raw roll fits, prior 100),
    a number = the mean of fit minus IMU with that prior; ``ou_s``: mean reversion to zero (s, 0 = off);
    ``slow``: (q, A, B) a slow second offset used while the fast one stays within A (+B ramp)."""
    t, y, z, R = a[:, 0:2], a[:, 2:4], a[:, 4:6], a[:, 6:8]
    out = np.zeros_like(t)
    for i in range(2):
        x, P, xs, Ps, bias, nb = 0.0, 4.0, 0.0, 4.0, 0.0, 0
        for j in range(len(a)):
            if ou_s[i]:
                x, P = x * np.exp(-0.05 / ou_s[i]), P * np.exp(-0.1 / ou_s[i])
            P += q[i] ** 2
            if np.isfinite(z[j, i]):
                zz = z[j, i]
                if i == 1:
                    nb += 1
                    ref = 0.0 if roll_bias_prior is None else y[j, i]
                    bias += (zz - ref - bias) / min(nb + (100 if roll_bias_prior is None else roll_bias_prior), 1200)
                    zz -= bias
                m, Rm = zz - y[j, i], k * R[j, i] + simu**2
                G = P / (P + Rm)
                x, P = x + G * (m - x), P * (1 - G)
                if slow:
                    Ps += slow[0] ** 2
                    Gs = Ps / (Ps + Rm)
                    xs, Ps = xs + Gs * (m - xs), Ps * (1 - Gs)
            g = x
            if slow:
                w = np.clip((abs(x - xs) - slow[1]) / slow[2], 0, 1)
                g = xs + w * (x - xs)
            out[j, i] = y[j, i] + g
    return np.median(np.abs(out - t), axis=0)


SERIES = [
    ("main: offset 0.05 deg a frame, image roll bias state", {}),
    ("IMU alone", {"q": (0.0, 0.0), "k": 1e12}),
    ("offset 0.02 / 0.05, fit variance x0.25", {"q": (0.02, 0.05), "k": 0.25}),
    ("offset 0.03 / 0.05, fit variance x0.25", {"q": (0.03, 0.05), "k": 0.25}),
    ("offset 0.01 / 0.05", {"q": (0.01, 0.05)}),
    ("roll bias against the IMU, prior 20", {"roll_bias_prior": 20}),
    ("roll bias against the IMU, prior 30", {"roll_bias_prior": 30}),
    ("roll bias against the IMU, prior 50", {"roll_bias_prior": 50}),
    ("roll offset reverting to zero in 2 s (image bias state)", {"ou_s": (0.0, 2.0)}),
    ("roll bias against the IMU 30 + roll offset reverting in 5 s", {"roll_bias_prior": 30, "ou_s": (0.0, 5.0)}),
    ("roll bias against the IMU 30, roll offset 0.03", {"roll_bias_prior": 30, "q": (0.05, 0.03)}),
    ("slow pitch offset 0.003, blend 0.04 / 0.02", {"slow": (0.003, 0.04, 0.02)}),
]


def rate_smoothed(bag: str, a: np.ndarray, qn: float) -> np.ndarray:
    """``a`` of :func:`series` with the IMU columns replaced by the IMU smoothed with its angular rate
    (random walk ``qn`` deg a sample around the rate-integrated prediction)."""
    from cone_perception.data.bags import read_imu_motion

    st, q, w, _ = read_imu_motion(bag)
    y = np.array([np.degrees(rpy_from_quaternion(*qq))[[1, 0]] for qq in q])
    rate = np.degrees(w[:, [1, 0]])  # pitch rate about y, roll rate about x
    xs, x, P, R = np.zeros_like(y), y[0].copy(), np.full(2, 0.03**2), 0.03**2
    for k in range(len(y)):
        if k:
            x, P = x + 0.5 * (rate[k - 1] + rate[k]) * (st[k] - st[k - 1]) / 1e9, P + qn**2
            G = P / (P + R)
            x, P = x + G * (y[k] - x), (1 - G) * P
        xs[k] = x
    b = a.copy()
    b[:, 2:4] = xs
    return b


def main(argv: list[str]) -> None:
    use_series, use_rate = "--series" in argv, "--imu-rate" in argv
    bags = [b.rstrip("/") for b in argv if not b.startswith("--")]
    kinds = {k: [b for b in bags if Path(b).name.startswith(k)] for k in ("jit", "car", "flat")}
    kinds = {k: v for k, v in kinds.items() if v}
    data = {b: cached(b) for b in bags}
    if use_series:
        S = {b: series(b, data[b]) for b in bags}
        print("| design | jit pitch | jit roll | car pitch | car roll |  (median abs error, deg: mean / worst drive)")
        print("|---|---|---|---|---|")
        for name, kw in SERIES:
            cells = []
            for v in kinds.values():
                r = np.array([offset_filter(S[b], **kw) for b in v])
                cells += [f"{r[:, 0].mean():.3f} / {r[:, 0].max():.3f}", f"{r[:, 1].mean():.3f} / {r[:, 1].max():.3f}"]
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
        return
    if use_rate:
        S = {b: series(b, data[b]) for b in bags}
        print("| IMU | jit pitch | jit roll | car pitch | car roll |  (median abs error, deg: mean / worst drive)")
        print("|---|---|---|---|---|")
        for qn in (None, 0.005, 0.01, 0.02):
            cells = []
            for v in kinds.values():
                r = np.array([offset_filter(S[b] if qn is None else rate_smoothed(b, S[b], qn), roll_bias_prior=30) for b in v])
                cells += [f"{r[:, 0].mean():.3f} / {r[:, 0].max():.3f}", f"{r[:, 1].mean():.3f} / {r[:, 1].max():.3f}"]
            name = "as read" if qn is None else f"smoothed with its rate, {qn} deg a sample"
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
        return
    print_design_table(kinds, DESIGNS + (STILL_DESIGNS if "flat" in kinds else []), lambda b, make: score(b, data[b], make))


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    main(sys.argv[1:])
