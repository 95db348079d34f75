"""``eval``'s pictures: confusion matrix, precision-recall curve, detection by distance, localisation box
plots, blue-yellow pair errors (PNG, matplotlib) and the worst frames with their errors drawn (JPEG).
:func:`cone_perception.evaluation.report.write_report` calls them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..classes import CLASS_BGR, CLASS_NAMES, CLASS_RGBA
from .groundtruth import EvalImage
from .localisation import DISTANCE_GROUPS, LocalisationReport, PairDistanceReport, distance_group
from .metrics import RECALL_POINTS, at_conf, match_by_class


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path


def plot_confusion(cm: np.ndarray, path: Path, title: str) -> Path:
    plt = _plt()
    labels = list(CLASS_NAMES) + ["background"]
    fig, ax = plt.subplots(figsize=(6.4, 5.4))
    rows = cm.sum(axis=1, keepdims=True)
    frac = np.divide(cm, rows, out=np.zeros(cm.shape), where=rows > 0)
    ax.imshow(frac, cmap="Blues", vmin=0.0, vmax=1.0)
    for i in range(cm.shape[0]):
        for j in range(cm.shape[1]):
            if cm[i, j]:
                ax.text(j, i, str(int(cm[i, j])), ha="center", va="center", color="white" if frac[i, j] > 0.5 else "black", fontsize=9)
    ax.set_xticks(range(len(labels)), labels, rotation=35, ha="right")
    ax.set_yticks(range(len(labels)), labels)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(title + "\ncolour: share of the row (row-normalised); numbers: counts", fontsize=10)
    return _save(fig, path)


def plot_pr(detection: dict, path: Path, title: str) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    curves = detection.get("pr50_per_class", {})
    for name, prec in curves.items():
        ax.plot(RECALL_POINTS, prec, color=CLASS_RGBA[CLASS_NAMES.index(name)], lw=2,
                label=f"{name} AP50 {detection['ap50_per_class'][name]:.3f}")
    if curves:
        ax.plot(RECALL_POINTS, np.mean(list(curves.values()), axis=0), color="black", lw=1.5, ls="--",
                label=f"mean mAP50 {detection['map50']:.3f}")
    op = detection["operating_point"]["per_class"]["all"]
    if not (math.isnan(op["precision"]) or math.isnan(op["recall"])):
        ax.plot([op["recall"]], [op["precision"]], "k*", ms=12, label=f"operating point (conf {detection['operating_point']['conf']:g})")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    return _save(fig, path)


def plot_by_distance(groups: dict, path: Path) -> Path:
    plt = _plt()
    names = list(groups)
    series = {
        "mAP@0.5": [g["map50"] for g in groups.values()],
        "mAP@0.5:0.95": [g["map50_95"] for g in groups.values()],
        "recall": [g["operating_point"]["per_class"]["all"]["recall"] for g in groups.values()],
        "precision": [g["operating_point"]["per_class"]["all"]["precision"] for g in groups.values()],
    }
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7.2, 4.2))
    w = 0.2
    for k, (label, vals) in enumerate(series.items()):
        ax.bar(x + (k - 1.5) * w, np.nan_to_num(vals), w, label=label)
    ax.set_xticks(x, [f"{n}\n({g['num_gt']} cones)" for n, g in groups.items()])
    ax.set_ylim(0, 1.05)
    ax.set_title("detection by distance group", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.18))
    return _save(fig, path)


def _group_values(values: np.ndarray, ranges: np.ndarray) -> list[np.ndarray]:
    g = distance_group(ranges)
    return [values[g == k] for k in range(len(DISTANCE_GROUPS))]


def _boxplot(ax, data: list[np.ndarray], title: str, ylabel: str) -> None:
    names = [n for n, _, _ in DISTANCE_GROUPS]
    pos = [i for i, d in enumerate(data) if d.size]
    if pos:
        ax.boxplot([data[i] for i in pos], positions=pos, widths=0.6, showfliers=True, flierprops={"markersize": 3})
    ax.set_xticks(range(len(names)), [f"{n}\nn={d.size}" for n, d in zip(names, data)], fontsize=8)
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set_title(title, fontsize=10)
    ax.set_ylabel(ylabel)
    ax.grid(axis="y", alpha=0.3)


def plot_localisation(loc: LocalisationReport, path: Path) -> Path:
    plt = _plt()
    ex, ey, er = np.asarray(loc.err_x), np.asarray(loc.err_y), np.asarray(loc.err_range)
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.4))
    _boxplot(axes[0], _group_values(ex, er), "error in x (forward)", "predicted - true (m)")
    _boxplot(axes[1], _group_values(ey, er), "error in y (left)", "predicted - true (m)")
    _boxplot(axes[2], _group_values(np.hypot(ex, ey), er), "position error", "distance to true position (m)")
    fig.suptitle("localisation error of matched cones by distance group", fontsize=11)
    return _save(fig, path)


def plot_pairs(pairs: PairDistanceReport, path: Path) -> Path:
    plt = _plt()
    e, er = np.asarray(pairs.err), np.asarray(pairs.err_range)
    fig, ax = plt.subplots(figsize=(6.8, 4.4))
    _boxplot(ax, _group_values(e, er), "blue-yellow pair distance error (thesis metric)", "measured - true distance (m)")
    return _save(fig, path)


def frame_errors(im: EvalImage, conf: float, iou: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One image at the operating point (class-aware, as precision / recall): masks of true-positive and
    false-positive detections (over ``im.pred_*``) and of missed cones (over ``im.gt_*``)."""
    keep = at_conf(im.pred_scores, conf)
    to_gt, ignored = match_by_class(im.pred_boxes[keep], im.pred_classes[keep], im.gt_boxes, im.gt_classes, im.gt_ignore, iou)
    tp, fp = np.zeros(len(im.pred_boxes), bool), np.zeros(len(im.pred_boxes), bool)
    tp[keep[to_gt >= 0]] = True
    fp[keep[(to_gt < 0) & ~ignored]] = True
    missed = ~im.gt_ignore.copy()
    missed[to_gt[to_gt >= 0]] = False
    return tp, fp, missed


def _frame_images(images: list[EvalImage], ks: list[int]) -> dict[int, np.ndarray]:
    """BGR images of ``images[k]`` for ``k`` in ``ks`` that can be read: image files (only those that exist, so
    OpenCV prints no warnings) and a bag's frames (read from the bag in one pass per bag)."""
    import cv2

    out: dict[int, np.ndarray] = {}
    by_bag: dict[str, dict[int, int]] = {}
    for k in ks:
        im = images[k]
        if im.bag_frame is not None:
            by_bag.setdefault(im.bag_frame[0], {})[int(im.bag_frame[1])] = k
        elif im.path and Path(im.path).is_file():
            img = cv2.imread(im.path, cv2.IMREAD_COLOR)
            if img is not None:
                out[k] = img
    if by_bag:
        from ..data.bags import read_bag_images
        from ..errors import ConePerceptionError

        for bag, stamp_to_k in by_bag.items():
            try:
                got = read_bag_images(bag, set(stamp_to_k))
            except (ConePerceptionError, OSError):
                continue
            out.update({stamp_to_k[st]: img for st, img in got.items()})
    return out


def _fit_text(img: np.ndarray, text: str, org: tuple[int, int], scale: float, color=(255, 255, 255)) -> None:
    """Outlined text at ``org``, its font made smaller until it fits the image's width."""
    import cv2

    from ..vis import outlined_text

    while scale > 0.3 and org[0] + cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] > img.shape[1] - 4:
        scale *= 0.9
    outlined_text(img, text, org, color, scale)


TILE_WIDTH = 960  # px, the width every tile of worst_frames.jpg is drawn at


def plot_worst_frames(images: list[EvalImage], conf: float, iou: float, path: Path, n: int = 6,
                      band_rows: tuple[int, int] | None = None) -> tuple[Path | None, list[dict]]:
    """The ``n`` frames with the most misses + false detections, drawn: detections found (green, thin),
    false detections (red, class and score), missed cones (magenta, class), ignore regions (grey), the
    band's rows (cyan). Images come from their files or, for a bag's frames, from the bag; frames whose
    image can't be read are skipped. -> (file or None, the frames' counts)."""
    import cv2

    from ..vis import frame_strip, outlined_text

    scored = []
    for k, im in enumerate(images):
        tp, fp, missed = frame_errors(im, conf, iou)
        scored.append((int(fp.sum() + missed.sum()), k, tp, fp, missed))
    scored.sort(key=lambda t: (-t[0], t[1]))
    candidates = [t for t in scored if t[0] > 0][: max(3 * n, n + 10)]
    pictures = _frame_images(images, [t[1] for t in candidates])
    tiles, listed = [], []
    for errors, k, tp, fp, missed in candidates:
        if len(tiles) == n:
            break
        im = images[k]
        img = pictures.get(k)
        if img is None:
            continue
        img = cv2.resize(img, (TILE_WIDTH, max(1, int(round(img.shape[0] * TILE_WIDTH / img.shape[1])))),
                         interpolation=cv2.INTER_AREA)
        sx, sy = img.shape[1] / im.width, img.shape[0] / im.height
        s = np.array([sx, sy, sx, sy])

        def rect(b, color, width, text=None):
            x1, y1, x2, y2 = (int(round(v)) for v in b * s)
            cv2.rectangle(img, (x1, y1), (x2, y2), color, width, cv2.LINE_AA)
            if text:
                outlined_text(img, text, (x1, max(12, y1 - 4)), color, 0.4)

        if band_rows is not None:
            for v in band_rows:
                cv2.line(img, (0, int(round(v * sy))), (img.shape[1], int(round(v * sy))), (255, 255, 0), 1, cv2.LINE_AA)
        for b in im.gt_boxes[im.gt_ignore]:
            rect(b, (128, 128, 128), 1)
        for b in im.pred_boxes[tp]:
            rect(b, (0, 200, 0), 1)
        for b, c, sc in zip(im.pred_boxes[fp], im.pred_classes[fp], im.pred_scores[fp]):
            rect(b, (0, 0, 255), 1, f"{CLASS_NAMES[c]} {sc:.2f}")
        for b, c in zip(im.gt_boxes[missed], im.gt_classes[missed]):
            rect(b, (255, 0, 255), 2, f"missed {CLASS_NAMES[c]}")
        _fit_text(img, f"{Path(im.image).name}", (8, 24), 0.7)
        _fit_text(img, f"{int(missed.sum())} missed, {int(fp.sum())} false, {int(tp.sum())} found", (8, 50), 0.7)
        tiles.append(img)
        listed.append({"image": im.image, "missed": int(missed.sum()), "false": int(fp.sum()), "found": int(tp.sum())})
    if not tiles:
        return None, listed
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), frame_strip(tiles, width=TILE_WIDTH, cols=2), [cv2.IMWRITE_JPEG_QUALITY, 88])
    return path, listed


def bag_frames_picture(bag: Path, boxes: dict, stamps: list[int], calib, path: Path, truth: dict | None = None,
                t0_ns: int | None = None) -> Path:
    """The picked frames in a 2-column grid: detections (class colour, score), the true cones' foot points
    (class-coloured rings, from ``/cones_gt`` through the calibration), the band, a time stamp per tile and
    a legend strip below."""
    import cv2

    from ..data.bags import read_bag_images
    from ..mapping import ConeMapper
    from ..vis import draw_boxes, frame_strip, legend_strip, outlined_text

    mapper = ConeMapper(calib)
    imgs = []
    t0 = stamps[0] if t0_ns is None and stamps else t0_ns
    frames = read_bag_images(bag, set(stamps))  # frames that do not decode are left out
    for stamp in sorted(frames):
        bgr = frames[stamp]
        k = max(1, bgr.shape[1] // 960)  # line and font size for a tile shown at 960 px
        img = draw_boxes(bgr, boxes.get(stamp, np.zeros(0)), thickness=k + 1, font_scale=0.45 * k,
                         min_label_height=14 * k)
        t = (truth or {}).get(stamp)
        if t is not None and len(t):
            t = t[t["score"] >= 0.5]  # at least half visible (score of /cones_gt: the visible fraction)
            uv = mapper.ground_to_pixels(np.c_[t["x"], t["y"]])
            for (u, v), c in zip(uv, t["class_id"]):
                if np.isfinite(u) and np.isfinite(v) and 0 <= u < img.shape[1] and 0 <= v < img.shape[0]:
                    cv2.circle(img, (int(round(u)), int(round(v))), 5 * k, (0, 0, 0), 3 * k, cv2.LINE_AA)
                    cv2.circle(img, (int(round(u)), int(round(v))), 5 * k, CLASS_BGR[int(c)], k, cv2.LINE_AA)
        c = calib.crop
        cv2.rectangle(img, (c.u0, c.v0), (c.u1 - 1, c.v1 - 1), (255, 255, 255), k)
        n = len(boxes.get(stamp, ()))
        outlined_text(img, f"t = {(stamp - t0) / 1e9:.2f} s   {n} detection{'s' if n != 1 else ''}",
                      (12 * k, 34 * k), (255, 255, 255), 0.9 * k, 2 * k)
        imgs.append(img)
    if not imgs:
        cv2.imwrite(str(path), np.zeros((8, 8, 3), np.uint8))
        return path
    grid = frame_strip(imgs, width=960, cols=2)
    legend = legend_strip(grid.shape[1], [
        ("box + class score: detection (score shown on boxes >= 14 px tall at 960 px)", (230, 230, 230)),
        ("ring: foot point of a true cone at least half visible (/cones_gt)", (230, 230, 230)),
        ("white frame: the band fed to the detector", (255, 255, 255)),
        *[(name.replace("_", " "), CLASS_BGR[i]) for i, name in enumerate(("blue", "yellow", "orange", "large_orange"))],
    ])
    cv2.imwrite(str(path), np.vstack([grid, legend]))
    return path
