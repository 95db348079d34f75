"""Tried and dropped (docs/benchmarks.md, "Fused attitude with the ground gate"): a constant-velocity
(angle, rate) filter per axis for the image attitude instead of the random walk, on the tuning drives
and cached boxes of attitude_designs.py, `image` mode, mean 7-15 m median error and attitude errors:

    .venv/bin/python docs/experiments/attitude_cv_filter.py /tmp/att/jit1?? /tmp/att/car1?? /tmp/att/flat1??
"""
import sys
sys.path.insert(0, "docs/experiments")
import numpy as np
from pathlib import Path
from attitude_designs import cached, run_drive
from cone_perception.attitude import ImageAttitude, ImageAttitudeConfig, Attitude


class CV(ImageAttitude):
    qa = 200.0  # deg/s^2 white acceleration spectral density sqrt
    dt = 0.05
    def reset(self):
        super().reset()
        self.X = np.zeros((2, 2))
        self.PP = np.array([np.diag([self.cfg.prior_sigma_deg**2, 10.0**2])] * 2)
    def update(self, boxes, class_ids):
        c, dt = self.cfg, self.dt
        F = np.array([[1.0, dt], [0.0, 1.0]])
        Q = self.qa**2 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        for i in range(2):
            self.X[i] = F @ self.X[i] * np.array([c.decay, 0.9])
            self.PP[i] = F @ self.PP[i] @ F.T + Q
        res = self.fit(boxes, class_ids, self.X[:, 0] + self.bias)
        source, n = "hold", 0
        if res is None or np.any(np.abs(res[0]) > c.max_abs_deg):
            wm = self.motion_weight(None, None)
        else:
            z, Rz, n = res
            wm = self.motion_weight(z, Rz)
            z = self.debias(z)
            for i in range(2):
                P = self.PP[i]
                K = P[:, 0] / (P[0, 0] + Rz[i, i])
                self.X[i] = self.X[i] + K * (z[i] - self.X[i, 0])
                self.PP[i] = P - np.outer(K, P[0])
            source = "image"
        sd = self.still_sigma(np.sqrt([self.PP[0][0, 0], self.PP[1][0, 0]]), wm)
        x = self.X[:, 0] * wm
        return Attitude(float(x[0]), float(x[1]), float(sd[0]), float(sd[1]), source, n)


bags = [b.rstrip("/") for b in sys.argv[1:]]
data = {b: cached(b) for b in bags}
kinds = {k: [b for b in bags if Path(b).name.startswith(k)] for k in ("jit", "car", "flat")}
def mk_plain(m, imu):
    return m.image_attitude(ImageAttitudeConfig())
designs = [("random walk (kept)", mk_plain)]
for qa in (50.0, 100.0, 200.0, 400.0):
    def mk(m, imu, qa=qa):
        e = m.image_attitude(ImageAttitudeConfig())
        e.__class__ = CV
        e.qa = qa
        e.reset()
        return e
    designs.append((f"CV qa {qa}", mk))
for name, mk in designs:
    r = {k: [run_drive(b, data[b], mk, False) for b in v] for k, v in kinds.items()}
    print(name, " ".join(f"{k} {np.mean([x[0] for x in v]):.3f} (pitch {np.mean([x[1] for x in v]):.3f} roll {np.mean([x[2] for x in v]):.3f})" for k, v in r.items()), flush=True)
