"""Quality report of a calibration: residuals, inliers, distance errors, warnings; as a dict and as text."""

from __future__ import annotations

import cv2
import numpy as np

from ..geometry import GroundMapper, apply_homography
from ..geometry.pose import pose_from_homography
from .fit import CalibrationResult

REPORT_DISTANCES_M = (5.0, 10.0, 15.0, 20.0)


# -- quality report ------------------------------------------------------------------------------
def quality_report(res: CalibrationResult, far_m: float = 10.0, max_range_m: float = 30.0) -> dict:
    """Numbers a person needs to accept a calibration (plain dict, JSON-able).

    Per point: raw pixel, true position in F, reprojection error (px, raw
    image) and ground error (m, in F), inlier flag. RMS over inliers. Coverage
    of the usable image (below the horizon, within ``max_range_m``) by the
    points' convex hull, and of the left / right edges and the far field
    (warnings when missing). Predicted ground error for a 1-px error at
    :data:`REPORT_DISTANCES_M` ahead. Pose from H when K is known.
    """
    W, Hh = res.width, res.height
    rep: dict = {"image_size": [W, Hh]}
    warnings = list(res.warnings)
    if len(res.pairs):
        _point_stats(res, rep, warnings, far_m, max_range_m)
    # predicted ground error for a one-pixel error, straight ahead
    K = None if res.intrinsics is None else res.intrinsics.K
    dist = None if res.intrinsics is None else res.intrinsics.dist
    gm = GroundMapper(res.H_F_B, 1e9, (1.0, 1.0), K, dist)
    pred = []
    for d in REPORT_DISTANCES_M:
        px, ok = res.ground_to_raw_px(np.array([[d, 0.0]]))
        row: dict = {"x_m": d, "u_px": None, "v_px": None, "m_per_px_v": None, "m_per_px_u": None, "in_image": False}
        if ok[0] and 0 <= px[0, 0] < W and 0 <= px[0, 1] < Hh:
            J = gm.jacobian(px)[0]
            row.update(
                u_px=float(px[0, 0]),
                v_px=float(px[0, 1]),
                m_per_px_v=float(np.linalg.norm(J[:, 1])),
                m_per_px_u=float(np.linalg.norm(J[:, 0])),
                in_image=True,
            )
        pred.append(row)
    rep["one_px_error"] = pred

    if K is not None:
        est = pose_from_homography(res.H_F_B, K)
        p = est.pose
        rep["pose_from_H"] = {
            "x_m": p.x_m,
            "y_m": p.y_m,
            "height_m": p.height_m,
            "pitch_deg": p.pitch_deg,
            "roll_deg": p.roll_deg,
            "yaw_deg": p.yaw_deg,
            "column_ratio": est.column_ratio,
            "column_angle_deg": est.column_angle_deg,
        }
        if abs(est.column_ratio - 1.0) > 0.05 or abs(est.column_angle_deg - 90.0) > 3.0:
            warnings.append(
                f"K does not fit H (|r1|/|r2| = {est.column_ratio:.3f}, angle {est.column_angle_deg:.1f} deg; want 1 and 90): "
                "wrong intrinsics, a bent board, or points off the ground plane; the pose estimate is unreliable"
            )
    if res.intrinsics is not None:
        rep["intrinsics"] = {
            "source": res.intrinsics.source,
            "camera_matrix": res.intrinsics.K.tolist(),
            "dist_coeffs": res.intrinsics.dist.tolist(),
            "calibrate_camera_rms_px": res.intrinsics.rms_px,
        }
    rep["warnings"] = warnings
    return rep


def _point_stats(res: CalibrationResult, rep: dict, warnings: list[str], far_m: float, max_range_m: float) -> None:
    """Per-point errors, RMS and coverage (+ warnings) of a calibration from point pairs."""
    W, Hh = res.width, res.height
    xy_F = res.xy_F()
    proj_px, front = res.ground_to_raw_px(xy_F)
    reproj = np.linalg.norm(proj_px - res.pairs.uv_px, axis=1)
    reproj[~front] = np.inf
    mapped, w = apply_homography(res.H_F_B, res.uv_und_px)
    ground = np.linalg.norm(mapped - xy_F, axis=1)
    ground[w <= 0] = np.inf
    inl = res.inliers
    points = [
        {
            "label": res.pairs.labels[k],
            "u_px": float(res.pairs.uv_px[k, 0]),
            "v_px": float(res.pairs.uv_px[k, 1]),
            "x_m": float(xy_F[k, 0]),
            "y_m": float(xy_F[k, 1]),
            "reproj_px": float(reproj[k]),
            "ground_err_m": float(ground[k]),
            "inlier": bool(inl[k]),
        }
        for k in range(len(res.pairs))
    ]
    rep.update(
        {
            "n_points": len(res.pairs),
            "n_board": int(res.pairs.is_board.sum()),
            "n_extra": int((~res.pairs.is_board).sum()),
            "n_inliers": int(inl.sum()),
            "outliers": [res.pairs.labels[k] for k in np.flatnonzero(~inl)],
            "rms_reproj_px": float(np.sqrt(np.mean(reproj[inl] ** 2))),
            "max_reproj_px": float(reproj[inl].max()),
            "rms_ground_m": float(np.sqrt(np.mean(ground[inl] ** 2))),
            "max_ground_m": float(ground[inl].max()),
            "points": points,
        }
    )

    # coverage of the usable image: grid of raw pixels below the horizon and within range
    gu, gv = np.meshgrid(np.linspace(0, W - 1, 96), np.linspace(0, Hh - 1, 54))
    grid = np.column_stack([gu.ravel(), gv.ravel()])
    gxy, gw = apply_homography(res.H_F_B, res.undistort(grid))
    with np.errstate(invalid="ignore"):
        usable = (gw > 0) & (np.hypot(gxy[:, 0], gxy[:, 1]) <= max_range_m)
    pts = res.pairs.uv_px[inl].astype(np.float32)
    hull = cv2.convexHull(pts)
    inside = np.array([cv2.pointPolygonTest(hull, (float(a), float(b)), False) >= 0 for a, b in grid[usable]])
    cover = float(inside.mean()) if inside.size else 0.0
    u_in = res.pairs.uv_px[inl, 0]
    rep["coverage"] = {
        "usable_image_fraction": float(usable.mean()),
        "hull_fraction_of_usable": cover,
        "u_span_px": [float(u_in.min()), float(u_in.max())],
        "v_span_px": [float(res.pairs.uv_px[inl, 1].min()), float(res.pairs.uv_px[inl, 1].max())],
        "max_distance_m": float(np.hypot(xy_F[inl, 0], xy_F[inl, 1]).max()),
        "max_x_m": float(xy_F[inl, 0].max()),
    }
    if cover < 0.3:
        warnings.append(
            f"points cover only {100 * cover:.0f} % of the usable image (below the horizon, within {max_range_m:g} m): "
            "H is extrapolated elsewhere; add reference points (cones at measured spots, --points)"
        )
    if not np.any(u_in < 0.2 * W):
        warnings.append("no point in the LEFT fifth of the image: errors grow towards the left edge (thesis ch. 4.4)")
    if not np.any(u_in > 0.8 * W):
        warnings.append("no point in the RIGHT fifth of the image: errors grow towards the right edge (thesis ch. 4.4)")
    if rep["coverage"]["max_x_m"] < far_m:
        warnings.append(
            f"far field not covered: the farthest point is {rep['coverage']['max_x_m']:.1f} m ahead (< {far_m:g} m); "
            "far cones rely on extrapolation: add points at 10-20 m"
        )
    uv = res.pairs.uv_px
    outside = (uv[:, 0] < 0) | (uv[:, 0] > W - 1) | (uv[:, 1] < 0) | (uv[:, 1] > Hh - 1)
    if np.any(outside):
        names = [res.pairs.labels[k] for k in np.flatnonzero(outside)]
        warnings.append(f"{len(names)} point(s) lie outside the {W}x{Hh} image: {', '.join(names[:8])}")
    if rep["n_inliers"] < len(res.pairs):
        warnings.append(f"{len(rep['outliers'])} point(s) rejected as outliers: {', '.join(rep['outliers'][:8])}")


def format_report(rep: dict, title: str = "calibration report", max_points: int | None = None) -> str:
    """The report as text for ``<name>.report.txt`` (all points) and the terminal (``max_points`` worst)."""
    L = [title, "=" * len(title)]
    if "n_points" not in rep:
        L.append(
            f"no point pairs (homography from the mount pose); image {rep['image_size'][0]}x{rep['image_size'][1]}"
        )
    else:
        _format_points_summary(L, rep)
    L.append("")
    L.append("ground error for a 1-px error, straight ahead:")
    for r in rep["one_px_error"]:
        if r["in_image"]:
            L.append(
                f"  {r['x_m']:4.0f} m (pixel {r['u_px']:.0f},{r['v_px']:.0f}): 1 px up/down -> {100 * r['m_per_px_v']:.1f} cm, "
                f"1 px left/right -> {100 * r['m_per_px_u']:.1f} cm"
            )
        else:
            L.append(f"  {r['x_m']:4.0f} m: not in the image")
    if "pose_from_H" in rep:
        p = rep["pose_from_H"]
        L.append("")
        L.append(
            f"camera pose from H and K (sanity check): x {p['x_m']:.3f} m, y {p['y_m']:.3f} m, "
            f"height {p['height_m']:.3f} m, pitch {p['pitch_deg']:.2f} deg, roll {p['roll_deg']:.2f} deg, "
            f"yaw {p['yaw_deg']:.2f} deg (K fit: |r1|/|r2| {p['column_ratio']:.3f}, angle {p['column_angle_deg']:.1f} deg)"
        )
    if "intrinsics" in rep:
        i = rep["intrinsics"]
        rms = f", calibrateCamera RMS {i['calibrate_camera_rms_px']:.3f} px" if i["calibrate_camera_rms_px"] else ""
        L.append(f"intrinsics: {i['source']}{rms}; dist_coeffs {np.round(i['dist_coeffs'], 5).tolist()}")
    if rep.get("points"):
        _format_points_table(L, rep, max_points)
    L.append("")
    if rep["warnings"]:
        L.extend(f"WARNING: {w}" for w in rep["warnings"])
    else:
        L.append("no warnings")
    return "\n".join(L) + "\n"


def _format_points_table(L: list[str], rep: dict, max_points: int | None) -> None:
    points = rep["points"]
    L.append("")
    if max_points is not None and len(points) > max_points:
        points = sorted(points, key=lambda p: (p["inlier"], -p["reproj_px"]))[:max_points]
        L.append(f"the {max_points} worst of {len(rep['points'])} points (all in the .report.txt file):")
    L.append(f"{'point':<22}{'u px':>8}{'v px':>8}{'x m':>8}{'y m':>8}{'reproj px':>11}{'ground cm':>11}  inlier")
    for p in points:
        L.append(
            f"{p['label']:<22}{p['u_px']:8.1f}{p['v_px']:8.1f}{p['x_m']:8.3f}{p['y_m']:8.3f}"
            f"{p['reproj_px']:11.2f}{100 * p['ground_err_m']:11.2f}  {'yes' if p['inlier'] else 'NO'}"
        )


def _format_points_summary(L: list[str], rep: dict) -> None:
    L.append(
        f"points: {rep['n_points']} ({rep['n_board']} board corners, {rep['n_extra']} extra), "
        f"inliers {rep['n_inliers']}"
    )
    L.append(
        f"reprojection error (inliers): RMS {rep['rms_reproj_px']:.2f} px, max {rep['max_reproj_px']:.2f} px; "
        f"ground error: RMS {100 * rep['rms_ground_m']:.1f} cm, max {100 * rep['max_ground_m']:.1f} cm"
    )
    c = rep["coverage"]
    L.append(
        f"coverage: points span u {c['u_span_px'][0]:.0f}..{c['u_span_px'][1]:.0f} px, "
        f"v {c['v_span_px'][0]:.0f}..{c['v_span_px'][1]:.0f} px of {rep['image_size'][0]}x{rep['image_size'][1]}; "
        f"their hull covers {100 * c['hull_fraction_of_usable']:.0f} % of the usable image; "
        f"farthest point {c['max_x_m']:.1f} m ahead"
    )
