"""Designs for `attitude: fused` with the IMU's rest attitude captured (docs/benchmarks.md, "Fused attitude
with the rest captured"): the ground offset (the road ahead against the IMU) taken from the image fits
only where they show it significantly, so that on ground without grade changes `fused` keeps the IMU's
accuracy. Tuning drives and cached boxes of docs/experiments/attitude_designs.py (never the held-out
seeds); the IMU's rest attitude of each drive is its exact bias, drawn again from the bag's seed (a
standing phase, `synth bag --stand`, gives it within its noise: 0.03 deg / sqrt(samples)).

    .venv/bin/python docs/experiments/attitude_gated_designs.py /tmp/att/jit1?? /tmp/att/car1?? /tmp/att/flat1??
    .venv/bin/python docs/experiments/attitude_gated_designs.py --trace /tmp/ho/jit313

``--trace BAG``: every 10th frame of one drive through the first gate (the current offset alone, no
one-second mean): the ground offset, its 1-sigma, the latch and the offset used (all
against the IMU, degrees; on these drives without grade changes the true offset is zero).
"""
import re
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from attitude_designs import cached, print_design_table, run_drive  # noqa: E402

from cone_perception.attitude import FusedAttitude, GroundGate, ImageAttitudeConfig  # noqa: E402
from cone_perception.synth.motion import IMU_ANGLE_BIAS_DEG  # noqa: E402


def rest_of(bag: str) -> tuple[float, float]:
    """The synthetic IMU's constant angle bias (pitch, roll) in degrees: synth/motion.py's first draw."""
    seed = int(re.sub(r"\D", "", Path(bag).name))
    b = np.random.default_rng([seed, 15]).normal(0.0, IMU_ANGLE_BIAS_DEG, 2)  # (roll, pitch)
    return float(b[1]), float(b[0])


def score(bag: str, d: dict, make, rest=True) -> tuple[float, float, float]:
    def mk(m, imu):
        return make(m.image_attitude(ImageAttitudeConfig()), imu)

    return run_drive(bag, d, mk, True, rest_of(bag) if rest else (0.0, 0.0))


def designs():
    def gate(**kw):
        g = GroundGate(**kw)
        return lambda e, i: FusedAttitude(e, i, gate=g)

    for rest in (False, True):
        r = "captured" if rest else "0,0"
        yield f"IMU alone, rest {r}", (lambda e, i: FusedAttitude(e, i, use_image=False)), rest
        yield f"fused before: no gate, rest {r}", (lambda e, i: FusedAttitude(e, i, gate=None)), rest
        yield f"**kept: gate {GroundGate()}**, rest {r}", (lambda e, i: FusedAttitude(e, i)), rest
    for kw in ({"evidence_frames": 1.0, "p_flat_instant": 0.5}, {"evidence_frames": 1.0, "p_flat_instant": 0.5, "hold_frames": 1.0},
               {"evidence_frames": 40.0}, {"p_flat_instant": 0.999}, {"p_flat": 0.3}, {"p_flat": 0.8},
               {"hold_frames": 1.0}, {"hold_frames": 1e9}, {"grade_deg": (1.0, 0.6)}, {"slow_deg": (0.06, 0.15)}):
        yield f"kept but {', '.join(f'{k} {v}' for k, v in kw.items())}, rest captured", gate(**kw), True


def trace(bag: str) -> None:
    d = cached(bag)
    gate = GroundGate(evidence_frames=1.0, p_flat_instant=0.5)
    seen = []

    def make(m, imu):
        est = FusedAttitude(m.image_attitude(ImageAttitudeConfig()), imu, gate=gate)
        step = est.step_ground_gate

        def logged():
            used = step()
            seen.append((est.g.copy(), np.sqrt(np.diag(est.Pg)), est.gate_latch.copy(), used[0].copy()))
            return used

        est.step_ground_gate = logged
        return est

    run_drive(bag, d, make, True, rest_of(bag))
    print("frame | offset (pitch, roll) | 1-sigma | latch | used")
    for k in range(0, len(seen), 10):
        g, sd, latch, used = seen[k]
        print(f"{k:5d} | {g[0]:+.3f} {g[1]:+.3f} | {sd[0]:.3f} {sd[1]:.3f} | {latch[0]:.2f} {latch[1]:.2f} | {used[0]:+.3f} {used[1]:+.3f}")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--trace"]:
        return trace(argv[1].rstrip("/"))
    bags = [b.rstrip("/") for b in argv if not b.startswith("--")]
    kinds = {k: [b for b in bags if Path(b).name.startswith(k)] for k in ("jit", "car", "flat")}
    kinds = {k: v for k, v in kinds.items() if v}
    data = {b: cached(b) for b in bags}
    print_design_table(kinds, [(name, (make, rest)) for name, make, rest in designs()],
                       lambda b, d: score(b, data[b], *d))


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    main(sys.argv[1:])
