"""Would a narrower far strip pay? Share of the true cones 15-40 m away (at least half visible) whose box
centre lies outside the central W px of the image, from a synthetic drive's ground truth (issue 26).

    .venv/bin/python docs/experiments/strip_width.py /tmp/d26/jit2601_gt.jsonl [/tmp/d26/jit2602_gt.jsonl ...]
"""
import json
import sys

import numpy as np

for path in sys.argv[1:]:
    us, ds, width = [], [], None
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            frame = json.loads(line)
            width = frame["width"]
            for c in frame["cones"]:
                d = float(np.hypot(c["x_m"], c["y_m"]))
                if c["visible_fraction"] >= 0.5 and 15.0 <= d <= 40.0:
                    us.append((c["box"][0] + c["box"][2]) / 2)
                    ds.append(d)
    us, ds = np.array(us), np.array(ds)
    for w in (width // 2, 2 * width // 3, 5 * width // 6):
        out = np.abs(us - width / 2) > w / 2
        print(f"{path}: {len(us)} cones 15-40 m; outside the central {w} of {width} px: {out.mean():.3f} "
              f"(25-40 m: {out[ds >= 25].mean():.3f})")
