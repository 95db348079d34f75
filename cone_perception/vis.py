"""Pictures people look at: boxes on frames, frame strips, bird's-eye plots of cones vs truth."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from .classes import CLASS_BGR, CLASS_NAMES, CLASS_RGBA
from .geometry import covariance_ellipses


def draw_boxes(
    bgr: np.ndarray,
    boxes: np.ndarray,
    scale: float = 1.0,
    thickness: int = 2,
    labels: bool = True,
    texts: Sequence[str] | None = None,
) -> np.ndarray:
    """Draw ``BOX_DTYPE`` records (image px, multiplied by ``scale``) on a copy of ``bgr``.

    Each label reads "class score", or ``texts[i]`` where given.
    """
    out = bgr.copy()
    for i, b in enumerate(boxes):
        cid = int(b["class_id"])
        color = CLASS_BGR[cid] if cid < len(CLASS_BGR) else (255, 255, 255)
        p1 = (int(round(b["u1"] * scale)), int(round(b["v1"] * scale)))
        p2 = (int(round(b["u2"] * scale)), int(round(b["v2"] * scale)))
        cv2.rectangle(out, p1, p2, color, thickness, cv2.LINE_AA)
        if labels:
            name = CLASS_NAMES[cid] if cid < len(CLASS_NAMES) else str(cid)
            text = texts[i] if texts is not None else f"{name} {float(b['score']):.2f}"
            (tw, _), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
            org = (max(0, min(p1[0], out.shape[1] - tw - 2)), max(12, p1[1] - 4))  # inside the image
            cv2.putText(out, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
            cv2.putText(out, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.45, color, 1, cv2.LINE_AA)
    return out


def frame_strip(frames: Sequence[np.ndarray], width: int = 960, cols: int = 2) -> np.ndarray:
    """Tile images (each resized to ``width`` px wide) into a grid with ``cols`` columns."""
    tiles = [cv2.resize(f, (width, int(round(f.shape[0] * width / f.shape[1]))), interpolation=cv2.INTER_AREA) for f in frames]
    h = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, h - t.shape[0]), (0, 0), (0, 0))) for t in tiles]
    while len(tiles) % cols:
        tiles.append(np.zeros_like(tiles[0]))
    rows = [np.hstack(tiles[i : i + cols]) for i in range(0, len(tiles), cols)]
    return np.vstack(rows)


def birdseye_plot(
    panels: Sequence[tuple[str, np.ndarray, np.ndarray | None]],
    path: str | Path,
    x_max_m: float = 30.0,
    y_half_m: float = 10.0,
    sigma_scale: float = 2.0,
) -> Path:
    """Save a PNG of one bird's-eye panel per ``(title, cones, truth)`` in the ``rear_axle`` frame.

    Detected cones are filled dots with their ``sigma_scale``-sigma covariance ellipse; true cones
    hollow circles. x (forward) is up and y (left) to the left, as a driver sees the track.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    n = len(panels)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 6.4), squeeze=False)
    for ax, (title, cones, truth) in zip(axes[0], panels):
        if truth is not None and len(truth):
            for cid in np.unique(truth["class_id"]):
                t = truth[truth["class_id"] == cid]
                ax.scatter(t["y"], t["x"], s=70, facecolors="none", edgecolors=[CLASS_RGBA[int(cid)]], linewidths=1.5)
        major, minor, yaw = covariance_ellipses(cones, sigma_scale) if len(cones) else ((), (), ())
        for c, a, b, yaw_i in zip(cones, major, minor, yaw):
            cid = int(c["class_id"])
            # plot axes are (y, x): a major axis at yaw from +x lies at 90 deg - yaw from the plot's first axis
            ax.add_patch(Ellipse((c["y"], c["x"]), a, b, angle=90.0 - np.degrees(yaw_i),
                                 facecolor=CLASS_RGBA[cid][:3] + (0.25,), edgecolor=CLASS_RGBA[cid][:3] + (0.6,)))
            ax.plot(c["y"], c["x"], "o", color=CLASS_RGBA[cid], markersize=4)
        ax.plot([0], [0], marker="s", color="k", markersize=6)
        ax.set_xlim(y_half_m, -y_half_m)  # y to the left, as seen from the driver's seat
        ax.set_ylim(-1, x_max_m)
        ax.set_aspect("equal")
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("y (m, positive = left)")
        ax.set_title(title, fontsize=9)
    axes[0][0].set_ylabel("x (m, forward of rear axle)")
    fig.suptitle("cones (dots, 2-sigma ellipses) vs truth (circles), rear_axle frame", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
