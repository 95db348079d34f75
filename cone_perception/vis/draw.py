"""Pictures people look at: boxes on frames, frame strips, bird's-eye plots of cones vs truth."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from ..classes import CLASS_BGR, CLASS_NAMES, CLASS_RGBA
from ..geometry import covariance_ellipses


def draw_boxes(bgr: np.ndarray, boxes: np.ndarray, scale: float = 1.0, thickness: int = 2, labels: bool = True,
               font_scale: float = 0.45, min_label_height: float = 0.0,
               texts: Sequence[str] | None = None) -> np.ndarray:
    """Draw ``BOX_DTYPE`` records (image px, multiplied by ``scale``) on a copy of ``bgr``.

    Labels ("class score", or ``texts[k]`` where given) are outlined, kept inside the image, placed
    largest box first, and left out where they would cover a label already placed (far cones crowd
    together; their boxes are still drawn); boxes less than ``min_label_height`` px tall get no label."""
    out = bgr.copy()
    order = sorted(range(len(boxes)), key=lambda k: -float(boxes[k]["v2"] - boxes[k]["v1"]))
    placed: list[tuple[int, int, int, int]] = []
    for k in order:
        b = boxes[k]
        cid = int(b["class_id"])
        color = CLASS_BGR[cid] if cid < len(CLASS_BGR) else (255, 255, 255)
        p1 = (int(round(b["u1"] * scale)), int(round(b["v1"] * scale)))
        p2 = (int(round(b["u2"] * scale)), int(round(b["v2"] * scale)))
        cv2.rectangle(out, p1, p2, color, thickness, cv2.LINE_AA)
        if labels and p2[1] - p1[1] >= min_label_height:
            name = CLASS_NAMES[cid] if cid < len(CLASS_NAMES) else str(cid)
            text = texts[k] if texts is not None else f"{name} {float(b['score']):.2f}"
            weight = max(1, int(round(font_scale / 0.45)))
            (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, weight)
            org = (max(0, min(p1[0], out.shape[1] - tw - 2)), max(th + 2, p1[1] - 4))  # inside the image
            rect = (org[0], org[1] - th - 2, org[0] + tw, org[1] + 2)
            if any(rect[0] < q[2] and q[0] < rect[2] and rect[1] < q[3] and q[1] < rect[3] for q in placed):
                continue
            placed.append(rect)
            outlined_text(out, text, org, color, font_scale, weight)
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
    from matplotlib.lines import Line2D

    present = sorted({int(c) for _, cones, truth in panels for arr in (cones, truth) if arr is not None
                      for c in np.asarray(arr["class_id"]).tolist()})
    handles = [Line2D([], [], marker="o", ls="", color=CLASS_RGBA[c], markersize=7, label=CLASS_NAMES[c].replace("_", " "))
               for c in present if c < len(CLASS_RGBA)]
    handles += [Line2D([], [], marker="o", ls="", color="0.3", markersize=4, label="detected cone (+ 2-sigma ellipse)"),
                Line2D([], [], marker="o", ls="", markerfacecolor="none", markeredgecolor="0.3", markersize=8,
                       label="true cone"),
                Line2D([], [], marker="s", ls="", color="k", markersize=6, label="rear axle (origin)")]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 4), fontsize=8, frameon=False)
    fig.suptitle("cones (dots, 2-sigma ellipses) vs truth (circles), rear_axle frame", fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def outlined_text(img: np.ndarray, text: str, org: tuple[int, int], color: tuple[int, int, int],
                  scale: float = 0.5, thickness: int = 1) -> None:
    """Draw ``text`` at ``org`` (bottom-left, px) in ``color`` with a black outline: readable on any background."""
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thickness + max(2, thickness), cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, thickness, cv2.LINE_AA)


def draw_band(bgr: np.ndarray, crop: Sequence[int], downscale: int = 1, color: tuple[int, int, int] = (0, 255, 0)
              ) -> np.ndarray:
    """The detection band ``V0,V1[,U0,U1]`` (full-image px) on a copy of ``bgr``: its rectangle, the image outside
    it darkened, and a label with its rows (and the downscale)."""
    out = bgr.copy()
    h, w = out.shape[:2]
    v0, v1, u0, u1 = crop if len(crop) == 4 else (*crop, 0, w)
    v0, v1, u0, u1 = (int(np.clip(v, 0, m)) for v, m in ((v0, h), (v1, h), (u0, w), (u1, w)))
    mask = np.ones((h, w), bool)
    mask[v0:v1, u0:u1] = False
    out[mask] = (out[mask] * 0.55).astype(out.dtype)
    cv2.rectangle(out, (u0, v0), (max(u0, u1 - 1), max(v0, v1 - 1)), color, 2, cv2.LINE_AA)
    text = f"band v {v0}..{v1}" + (f", u {u0}..{u1}" if len(crop) == 4 else "") + (f", /{downscale}" if downscale > 1 else "")
    outlined_text(out, text, (u0 + 6, v0 + 20 if v0 + 20 < v1 else max(14, v0 - 6)), color)
    return out


def legend_strip(width: int, items: Sequence[tuple[str, tuple[int, int, int]]], height: int = 34) -> np.ndarray:
    """A dark strip ``width`` px wide with ``items`` (text, BGR colour) side by side, each after a colour swatch;
    wraps to more rows when they do not fit."""
    rows: list[list[tuple[str, tuple[int, int, int], int]]] = [[]]
    x = 10
    for text, color in items:
        tw = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0] + 40
        if x + tw > width and rows[-1]:
            rows.append([])
            x = 10
        rows[-1].append((text, color, x))
        x += tw
    out = np.full((height * len(rows), width, 3), 32, np.uint8)
    for r, row in enumerate(rows):
        y = r * height + height // 2
        for text, color, x0 in row:
            cv2.rectangle(out, (x0, y - 7), (x0 + 14, y + 7), color, -1)
            cv2.putText(out, text, (x0 + 20, y + 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (235, 235, 235), 1, cv2.LINE_AA)
    return out
