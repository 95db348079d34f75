"""The still test's window and threshold (docs/attitude.md, "still test"; docs/benchmarks.md, "Fused
attitude with the ground gate") on the tuning drives and cached boxes of attitude_designs.py, `image`
and `fused` (IMU rest 0,0): mean of the per-drive 7-15 m medians per kind (max over the drives). The
first row is the configuration the script runs with (the package's current defaults).

    .venv/bin/python docs/experiments/attitude_still_designs.py /tmp/att/jit1?? /tmp/att/car1?? /tmp/att/flat1??
"""
import sys
sys.path.insert(0, "docs/experiments")
import numpy as np
from pathlib import Path
from attitude_designs import cached, score  # noqa: E402
from cone_perception.attitude import GroundGate  # noqa: E402
bags = [b.rstrip("/") for b in sys.argv[1:]]
data = {b: cached(b) for b in bags}
kinds = {k: [b for b in bags if Path(b).name.startswith(k)] for k in ("jit", "car", "flat")}
for cfg in ({}, {"still_frames": 20.0, "still_ratio": 1.0}, {"still_frames": 20.0, "still_ratio": 1.3}, {"still_ratio": 1.6},
            {"still_ratio": 1.0}, {"still_frames": 20.0, "still_ramp": 0.2}):
    for mode in ("image", "fused"):
        r = {k: [score(b, data[b], mode, cfg, GroundGate()) for b in v] for k, v in kinds.items()}
        print(cfg, mode, " ".join(f"{k} {np.mean([x[0] for x in v]):.4f} (max {np.max([x[0] for x in v]):.3f})" for k, v in r.items()), flush=True)
