"""Camera calibration to the rear axle (``cone-perception calibrate``; the calibration file itself: ``calib.py``).

* :mod:`.points`: the inputs: point pairs from a CSV file or a chessboard on the ground, ``T_F_S``;
* :mod:`.fit`: point pairs -> ``H_S_B`` -> ``H_F_B``, mount pose <-> homography, lens intrinsics;
* :mod:`.report`: the quality report (residuals, distance errors, warnings);
* :mod:`.pictures`: the pictures that prove a calibration.

The names below are this package's face (``from cone_perception.calibrate import fit_calibration``).
"""

from ..geometry.pose import PoseEstimate, from_pose, pose_from_homography
from .fit import (
    DEFAULT_RANSAC_PX, CalibrationResult, Intrinsics, calibrate_intrinsics, default_crop, estimate_homography,
    fit_calibration, read_intrinsics_file, result_from_pose,
)
from .points import (
    Board, PointPairs, board_not_found_hint, board_pairs, detect_board, planar_transform, read_points_csv,
)
from .report import REPORT_DISTANCES_M, format_report, quality_report

__all__ = [
    "DEFAULT_RANSAC_PX", "REPORT_DISTANCES_M", "Board", "CalibrationResult", "Intrinsics", "PointPairs", "PoseEstimate",
    "board_not_found_hint", "board_pairs", "calibrate_intrinsics", "default_crop", "detect_board", "estimate_homography",
    "fit_calibration", "format_report", "from_pose", "planar_transform", "pose_from_homography", "quality_report",
    "read_intrinsics_file", "read_points_csv", "result_from_pose",
]
