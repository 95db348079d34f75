"""Recall and false cones by range band (issue 26), from `replay --gt-topic --track --json` summaries.

    .venv/bin/python docs/experiments/range_bands.py OUT.png "LABEL=SUMMARY.json" ...

Each SUMMARY.json is what `cone-perception replay BAG --calib BAG_calib.yaml --gt-topic /cones_gt --track
--json SUMMARY.json [settings]` writes for a synthetic drive. Prints one markdown row per summary
(/cones, and /cones/tracked where the summary has it: recall per band and false cones per frame within
40 m) and plots recall by band for /cones (solid) and /cones/tracked (hatched) per label into OUT.png.
Bands and their rules: cone_perception/evaluation/localisation.py (EXTRA_GROUPS, GT_MIN_VISIBLE).
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

out, runs = sys.argv[1], [a.split("=", 1) for a in sys.argv[2:]]
rows, bars = [], []
for label, path in runs:
    s = json.loads(open(path, encoding="utf-8").read())
    loc = s["localisation"]
    bands = loc["extra_groups"]
    names = list(bands)
    raw = [bands[n]["recall"] for n in names]
    tr = s.get("tracking") or {}
    tb = tr.get("tracked", {}).get("bands")
    rows.append(f"| {label} | /cones | " + " | ".join(f"{bands[n]['recall']:.3f}" for n in names)
                + f" | {loc['bands']['false_per_frame']:.2f} |")
    if tb:
        f = sum(b["false_cones"] for b in tb.values()) / tr["tracked"]["frames"]
        rows.append(f"| {label} | /cones/tracked | " + " | ".join(f"{tb[n]['recall']:.3f}" for n in names) + f" | {f:.2f} |")
    f_raw = loc["bands"]["false_per_frame"]
    f_tr = sum(b["false_cones"] for b in tb.values()) / tr["tracked"]["frames"] if tb else None
    bars.append((label, raw, [tb[n]["recall"] for n in names] if tb else None, f_raw, f_tr))
print("| setting | topic | " + " | ".join(names) + " | false cones per frame (< 40 m) |")
print("|---|---|" + "---|" * len(names) + "---|")
print("\n".join(rows))

fig, ax = plt.subplots(figsize=(11.0, 3.8))
x = np.arange(len(names))
k = sum(1 + (t is not None) for _, _, t, _, _ in bars)
w, i = 0.8 / k, 0
colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
for j, (label, raw, tracked, f_raw, f_tr) in enumerate(bars):
    ax.bar(x - 0.4 + (i + 0.5) * w, raw, w, color=colors[j % len(colors)], label=f"{label}: /cones ({f_raw:.2f} false/frame)")
    i += 1
    if tracked is not None:
        ax.bar(x - 0.4 + (i + 0.5) * w, tracked, w, color=colors[j % len(colors)], alpha=0.45, hatch="//",
               label=f"{label}: /cones/tracked ({f_tr:.2f} false/frame)")
        i += 1
for t, c in ((0.98, "15-25 m"), (0.80, "25-40 m")):
    xi = names.index(c)
    ax.plot([xi - 0.45, xi + 0.45], [t, t], "k--", lw=1)
ax.set_xticks(x, names)
ax.set_ylim(0, 1.05)
ax.set_ylabel("recall (cones >= half visible)")
ax.set_xlabel("range from the rear axle")
ax.set_title("recall by range band (dashed: issue 26 targets for /cones)", fontsize=10)
ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), title="false cones: within 40 m", title_fontsize=7)
fig.tight_layout()
fig.savefig(out, dpi=80)
print(f"wrote {out}")
