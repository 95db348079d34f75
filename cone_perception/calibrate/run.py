"""The ``cone-perception calibrate`` run: read the image or pose, fit, write the calibration YAML, its report
and pictures (the command parses the arguments; see ``calib/README.md`` for the procedure).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import shlex
import sys
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from ..classes import CLASS_NAMES
from ..data.outfiles import json_safe, print_written, refuse_existing
from ..data.sources import read_bag_image, read_image
from ..errors import ConfigError
from ..geometry.calib import (
    DEFAULT_MAX_RANGE_M, RECOMMENDED_FOOT_OFFSET_M, RECOMMENDED_FOOT_POINTS, Calibration, calibration_from_dict,
    load_calibration, save_calibration,
)
from ..geometry.camera import MountPose, default_intrinsics
from ..geometry.pose import MOUNT_POSE_CHECK_RANGE_M, MOUNT_POSE_TOLERANCE, mount_pose_disagreement
from ..words import parse_size
from . import (
    Board, CalibrationResult, Intrinsics, PointPairs, board_not_found_hint, board_pairs, calibrate_intrinsics,
    default_crop, detect_board, fit_calibration, format_report, planar_transform, quality_report, read_intrinsics_file,
    read_points_csv, result_from_pose,
)
from .pictures import birdseye_picture, not_found_picture, points_picture

BOARD_SIZE = "COLSxROWS (e.g. 9x6)"
# keys of the YAML's free part that the command owns (rewritten on every run)
_OWNED_EXTRA = ("mount", "mount_estimate", "calibration")


def command_line(args: argparse.Namespace, defaults: dict) -> str:
    """The ``cone-perception calibrate`` command that reproduces ``args``: the options that differ from their
    ``defaults`` (option dest -> default value)."""
    parts = ["cone-perception", "calibrate"]
    for key, value in vars(args).items():
        if key not in defaults or value == defaults[key]:
            continue
        opt = "--" + key.replace("_", "-")
        if value is True:
            parts.append(opt)
        elif isinstance(value, list):
            parts += [opt] + [str(v) for v in value]
        else:
            parts += [opt, f"{value:g}" if isinstance(value, float) else str(value)]
    return " ".join(shlex.quote(x) for x in parts)


def run_calibrate(args: argparse.Namespace, defaults: dict) -> int:
    """Calibrate as ``args`` (the parsed options of ``cone-perception calibrate``) say; ``defaults``: the options'
    defaults (dest -> value), for the command that reproduces ``args`` (:func:`command_line`), written into the
    YAML's header. Returns the exit code."""
    camera, out = _names(args)
    stem = out.with_suffix("")
    refuse_existing([out, *(Path(f"{stem}{s}") for s in (".report.txt", ".report.json", ".points.png", ".birdseye.png"))],
                    args.force, "calibrate")
    existing = load_calibration(out) if out.is_file() else None
    size = parse_size(args.size, "--size", "WxH (e.g. 1920x1080)") if args.size else None

    image, image_name = _read_input_image(args)
    if image is not None:
        img_size = (image.shape[1], image.shape[0])
        if size is not None and size != img_size:
            raise ConfigError(
                image_name, None, f"image is {img_size[0]}x{img_size[1]} but --size says {size[0]}x{size[1]}"
            )
        size = img_size
    if size is None and existing is not None:
        size = (existing.image_width, existing.image_height)
    intr = _intrinsics(args, existing, out, size)
    if size is None:  # from-pose without --size: the size of the views / intrinsics file, else full HD
        size = intr.image_size if intr is not None and intr.image_size is not None else (1920, 1080)
    W, H = size

    T_F_S = planar_transform(args.x_offset, args.y_offset, args.yaw)
    if args.from_pose:
        res, extra = _from_pose(args, intr, W, H, T_F_S)
        title = f"calibration report: {camera} (from mount pose)"
    else:
        if image is None:
            raise ConfigError("calibrate", "--image", "give --image IMG or --bag BAG --frame N (or --from-pose)")
        pairs = _collect_pairs(args, image, image_name, T_F_S, out)
        res = fit_calibration(pairs, W, H, T_F_S, intr, args.ransac_px, image_name)
        extra = {
            "calibration": {
                "method": "chessboard" if args.board else "points",
                "image": image_name,
                "date": datetime.date.today().isoformat(),
            }
        }
        title = f"calibration report: {camera} ({image_name})"
    max_range = existing.max_range_m if existing else DEFAULT_MAX_RANGE_M
    rep = quality_report(res, args.far_m, max_range)
    if not args.from_pose and "pose_from_H" in rep:
        extra["mount_estimate"] = {
            k: round(float(v), 4)
            for k, v in rep["pose_from_H"].items()
            if k in ("x_m", "y_m", "height_m", "pitch_deg", "roll_deg", "yaw_deg")
        }
    if "rms_reproj_px" in rep:
        extra["calibration"].update(
            rms_reproj_px=round(rep["rms_reproj_px"], 4), n_points=rep["n_points"], n_inliers=rep["n_inliers"]
        )

    calib = _build_calibration(camera, res, existing, extra, out)
    calib.mount_pose = _mount_pose(args, rep, calib)
    save_calibration(calib, out, header=f"written by: {command_line(args, defaults)}")

    text = format_report(rep, title)
    stem = out.with_suffix("")
    Path(f"{stem}.report.txt").write_text(text, encoding="utf-8")
    Path(f"{stem}.report.json").write_text(json.dumps(json_safe(rep), indent=1, allow_nan=False), encoding="utf-8")
    print(format_report(rep, title, max_points=8), end="")
    written = [out, Path(f"{stem}.report.txt"), Path(f"{stem}.report.json")]
    if image is not None:
        cv2.imwrite(f"{stem}.points.png", points_picture(image, res, rep if len(res.pairs) else None))
        cv2.imwrite(f"{stem}.birdseye.png", birdseye_picture(image, res))
        written += [Path(f"{stem}.points.png"), Path(f"{stem}.birdseye.png")]
    print_written(written, "calibrate")
    return 0


# -- pieces ------------------------------------------------------------------------------------
def _names(args: argparse.Namespace) -> tuple[str, Path]:
    if args.out is None and not args.camera:
        raise ConfigError("calibrate", "--camera", "give --camera NAME or --out FILE.yaml")
    out = args.out if args.out is not None else Path("calib") / f"{args.camera}.yaml"
    if out.suffix not in (".yaml", ".yml"):
        raise ConfigError(str(out), "--out", "must end in .yaml or .yml")
    return (args.camera or out.stem), out


def _read_input_image(args: argparse.Namespace) -> tuple[np.ndarray | None, str]:
    if args.image is not None and args.bag is not None:
        raise ConfigError("calibrate", "--image/--bag", "give one of --image and --bag, not both")
    if args.image is not None:
        return read_image(args.image), str(args.image)
    if args.bag is not None:
        img, where = read_bag_image(args.bag, args.frame, args.topic)
        return img, where
    return None, ""


def _intrinsics(
    args: argparse.Namespace, existing: Calibration | None, out: Path, size: tuple[int, int] | None
) -> Intrinsics | None:
    """K and lens model, first of: --views, --intrinsics, --hfov, the existing --out file; else None.

    ``size``: the calibration image size when already known (image, --size, existing file).
    """
    intr = _intrinsics_source(args, existing, out, size or (1920, 1080))
    if intr is not None and intr.image_size is None and args.hfov is not None:
        intr.image_size = size or (1920, 1080)
    if size is not None and intr is not None and intr.image_size is not None and tuple(intr.image_size) != tuple(size):
        raise ConfigError(
            intr.source,
            "image size",
            f"intrinsics are for {intr.image_size[0]}x{intr.image_size[1]} images, the calibration image is {size[0]}x{size[1]}",
        )
    return intr


def _intrinsics_source(
    args: argparse.Namespace, existing: Calibration | None, out: Path, size: tuple[int, int]
) -> Intrinsics | None:
    if sum(x is not None and x is not False for x in (args.views, args.intrinsics, args.hfov)) > 1:
        raise ConfigError("calibrate", "--views/--intrinsics/--hfov", "give only one source of intrinsics")
    if args.hfov is not None:
        if not 1.0 < args.hfov < 179.0:
            raise ConfigError("calibrate", "--hfov", f"must be between 1 and 179 degrees, got {args.hfov:g}")
        K = default_intrinsics(size[0], size[1], args.hfov)
        return Intrinsics(K, np.zeros(0), f"--hfov {args.hfov:g} (square pixels, centred)")
    if args.views:
        board, square = args.views_board or args.board, args.views_square or args.square
        if not (board and square):
            raise ConfigError(
                "calibrate",
                "--views",
                "needs the board in the views: --views-board/--board and --views-square/--square",
            )

        views = [
            (str(v), read_image(v))
            for v in tqdm(args.views, desc="reading views", unit="img", disable=len(args.views) < 4 or args.no_progress)
        ]
        intr, missed = calibrate_intrinsics(views, parse_size(board, "--views-board", BOARD_SIZE), square)
        if missed:
            print(f"board not found in {len(missed)} view(s), not used: {', '.join(missed)}", file=sys.stderr)
        return intr
    if args.intrinsics:
        return read_intrinsics_file(args.intrinsics)
    if existing is not None and existing.camera_matrix is not None and not args.no_intrinsics:
        d = existing.dist_coeffs if existing.dist_coeffs is not None else np.zeros(0)
        return Intrinsics(existing.camera_matrix, d, f"kept from {out}")
    return None


def _collect_pairs(
    args: argparse.Namespace, image: np.ndarray, image_name: str, T_F_S: np.ndarray, out: Path
) -> PointPairs:
    pairs = PointPairs.empty()
    if args.board:
        if not args.square or args.square <= 0:
            raise ConfigError("calibrate", "--square", "give the board's square size in metres (> 0) with --board")
        size = parse_size(args.board, "--board", BOARD_SIZE)
        try:
            bx, by, byaw = (float(v) for v in args.board_pose.split(","))
        except ValueError:
            raise ConfigError(
                "calibrate", "--board-pose", f"must be X,Y,YAW (m, m, deg), got {args.board_pose!r}"
            ) from None
        corners = detect_board(image, size)
        if corners is None:
            hint, found = board_not_found_hint(image, size)
            pic = Path(f"{out.with_suffix('')}.board_not_found.png")
            pic.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(pic), not_found_picture(image, found, size, hint))
            raise ConfigError(image_name, "--board", f"no {size[0]}x{size[1]} chessboard found; {hint}. Picture: {pic}")
        pairs = board_pairs(corners, Board(size[0], size[1], args.square, bx, by, byaw), T_F_S)
    if args.points:
        pairs = pairs + read_points_csv(args.points)
    if not len(pairs):
        raise ConfigError(
            "calibrate", "--board/--points", "give a chessboard (--board, --square) and/or --points FILE.csv"
        )
    return pairs


def _from_pose(args: argparse.Namespace, intr: Intrinsics | None, W: int, H: int, T_F_S: np.ndarray):
    if intr is None:
        raise ConfigError("calibrate", "--from-pose", "needs K: --hfov DEG, --intrinsics FILE or --views IMG...")
    if args.height is None or args.pitch is None:
        raise ConfigError("calibrate", "--from-pose", "needs at least --height M and --pitch DEG of the camera")
    if args.height <= 0:
        raise ConfigError("calibrate", "--height", f"must be > 0 (camera above the ground), got {args.height}")
    pose = MountPose(args.cam_x, args.cam_y, args.height, args.pitch, args.roll, args.cam_yaw)
    res = result_from_pose(intr, W, H, pose, T_F_S)
    mount = dataclasses.asdict(pose)
    if args.hfov is not None:
        mount["hfov_deg"] = args.hfov
    return res, {"mount": mount, "calibration": {"method": "from_pose", "date": datetime.date.today().isoformat()}}


def _mount_pose(args: argparse.Namespace, rep: dict, calib: Calibration) -> MountPose | None:
    """The ``mount_pose`` to write: the given pose (``--from-pose``), else the pose recovered from H
    when K is known (then it agrees with H by construction), else none (attitude stays fixed)."""
    if calib.camera_matrix is None:
        return None
    if args.from_pose:
        return MountPose(args.cam_x, args.cam_y, args.height, args.pitch, args.roll, args.cam_yaw)
    p = rep.get("pose_from_H")
    if not p:
        return None
    pose = MountPose(*(float(p[k]) for k in ("x_m", "y_m", "height_m", "pitch_deg", "roll_deg", "yaw_deg")))
    bad = mount_pose_disagreement(calib.H_F_B, calib.camera_matrix, pose, calib.image_width, calib.image_height)
    if not bad <= MOUNT_POSE_TOLERANCE:
        print(f"note: no mount_pose written: the pose recovered from H disagrees with H by {bad * 100:.1f} % at "
              f"{MOUNT_POSE_CHECK_RANGE_M:g} m (H is not a rigid camera pose with this K); attitude stays fixed")
        return None
    return pose


def _build_calibration(
    camera: str, res: CalibrationResult, existing: Calibration | None, extra: dict, out: Path
) -> Calibration:
    intr = res.intrinsics
    K = None if intr is None else intr.K
    dist = None if intr is None or not intr.dist.size else intr.dist
    if existing is not None:
        if (existing.image_width, existing.image_height) != (res.width, res.height):
            raise ConfigError(
                str(out),
                "image_width/image_height",
                f"existing file is for {existing.image_width}x{existing.image_height}, the new calibration for "
                f"{res.width}x{res.height}: write to a new --out or fix the file",
            )
        kept = {k: v for k, v in existing.extra.items() if k not in _OWNED_EXTRA}
        calib = dataclasses.replace(
            existing,
            camera=camera,
            H_S_B=res.H_S_B,
            T_F_S=res.T_F_S,
            camera_matrix=K,
            dist_coeffs=dist,
            extra={**kept, **extra},
        )
    else:
        calib = Calibration(
            camera=camera,
            image_width=res.width,
            image_height=res.height,
            H_S_B=res.H_S_B,
            T_F_S=res.T_F_S,
            crop=default_crop(res),
            foot_points=tuple(RECOMMENDED_FOOT_POINTS[n] for n in CLASS_NAMES),
            foot_offset_m=tuple(RECOMMENDED_FOOT_OFFSET_M[n] for n in CLASS_NAMES),
            camera_matrix=K,
            dist_coeffs=dist,
            extra=extra,
        )
    try:
        calib.strip_plan()
    except ConfigError as e:  # this camera cannot place the far strip: the file says so instead of failing to load
        print(f"calibrate: far strip off for this camera ({e.message})", file=sys.stderr)
        calib = dataclasses.replace(calib, far_strip=None)
    return calibration_from_dict(calib.to_dict(), str(out))  # the file we write must load
