"""What a training run leaves for people: its numbered output folder and ``results.png``."""

from __future__ import annotations

import csv
import re
from pathlib import Path

from ..errors import ConfigError
from ..vis import pyplot

#: Where ``cone-perception train`` writes when no ``--out`` is given: ``runs/train/<name>``, numbered.
RUNS_DIR = Path("runs") / "train"


def next_run_dir(parent: str | Path, name: str) -> Path:
    """A folder under ``parent`` that does not exist yet: ``name``, else ``name2``, ``name3``, ... (never reused)."""
    parent = Path(parent)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name or ""):
        raise ConfigError("--name", None, f"must be letters, digits, '_', '-' or '.', got {name!r}")
    cand, k = parent / name, 2
    while cand.exists():
        cand, k = parent / f"{name}{k}", k + 1
    return cand


def read_results(path: str | Path) -> list[dict]:
    """Rows of a ``results.csv`` with numbers as floats (``epoch`` as int)."""
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            row = {}
            for k, v in r.items():
                try:
                    row[k] = int(v) if k == "epoch" else float(v)
                except (TypeError, ValueError):
                    row[k] = v
            rows.append(row)
    return rows


def plot_results(rows: list[dict], png: str | Path, title: str = "") -> Path:
    """``results.png``: training losses, validation mAP and learning rate per epoch (epochs numbered from 1,
    as in the progress bar, the log and results.csv)."""
    plt = pyplot()

    ep = [r["epoch"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    ax = axes[0]
    for key, label in (("box_loss", "box (CIoU)"), ("cls_loss", "class (BCE)"), ("dfl_loss", "DFL")):
        if rows and key in rows[0]:
            ax.plot(ep, [r[key] for r in rows], marker="o", ms=3, label=label)
    ax.set_title("training loss (mean per epoch)")
    ax.set_ylabel("loss")
    ax.legend(loc="best")
    ax = axes[1]
    if rows and "map50" in rows[0]:
        ax.plot(ep, [r["map50"] for r in rows], marker="o", ms=3, label="mAP@0.5")
        ax.plot(ep, [r["map50_95"] for r in rows], marker="o", ms=3, label="mAP@0.5:0.95")
        ax.set_ylim(0, max(1e-3, max(max(r["map50"] for r in rows) * 1.1, 0.05)))
        ax.legend(loc="lower right")
    else:
        ax.text(0.5, 0.5, "no validation split\n(no val: in the data YAML)", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_title("validation mAP (EMA weights)")
    ax = axes[2]
    ax.plot(ep, [r["lr"] for r in rows], marker="o", ms=3, color="tab:gray")
    ax.set_title("learning rate (at the epoch's last batch)")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    for ax in axes:
        ax.set_xlabel("epoch")
        ax.grid(alpha=0.3)
        if ep:
            ax.set_xlim(0.5, max(ep) + 0.5)
            ax.xaxis.get_major_locator().set_params(integer=True)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    png = Path(png)
    tmp = png.with_name(png.stem + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    tmp.replace(png)
    return png
