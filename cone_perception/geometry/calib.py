"""Per-camera calibration YAML: load, validate, compose ``H_F_B``, save.

Fields (see ``calib/README.md``): ``camera``, ``image_width``, ``image_height``,
``H_S_B`` (3x3 rows), ``T_F_S`` (3x3 rows), ``crop`` (``v0``, ``v1``, optional
``u0``, ``u1``), ``downscale``, ``foot_points`` (class name -> rule),
``max_range_m``, ``pixel_sigma`` (``u``, ``v``); optional ``frame_id``
(default ``rear_axle``), ``camera_matrix`` (3x3), ``dist_coeffs`` (list), ``mount_pose``
(``x_m y_m z_m yaw_deg pitch_deg roll_deg``: lets the mapping recompose ``H_F_B`` for a body attitude
offset, see :mod:`cone_perception.attitude`), ``far_strip`` (``off``, or ``near_m far_m pitch_margin_deg
roll_margin_deg``: the far strip's range and margins, :mod:`.strip`; absent = the defaults).
Other keys are kept as they are (``extra``) and written back on save.

Every problem raises :class:`~cone_perception.errors.ConfigError` naming the
file and the field.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..classes import CLASS_NAMES
from ..crop import MAX_IMAGE_SIDE_PX, CropSpec
from ..errors import ConfigError
from ..resources import calib_dir, resolve_in
from .camera import MountPose, PinholeCamera
from .homography import FOOT_RULES, fix_homography_sign
from .pose import MOUNT_POSE_CHECK_RANGE_M, MOUNT_POSE_TOLERANCE, mount_pose_disagreement, pose_from_homography
from .strip import DEFAULT_STRIP, FarStripSpec, StripPlan, plan_strip, strip_spec_from_yaml

DEFAULT_FOOT_POINTS = {
    "blue": "bottom_right",
    "yellow": "bottom_left",
    "orange": "bottom_center",
    "large_orange": "bottom_center",
    "unknown": "bottom_center",
}
DEFAULT_CAMERA = "example_mainhoop"
#: ``max_range_m`` where a calibration does not say: cones farther are not published. 40 m: the far
#: strip's reach (docs/benchmarks.md, "Far cones by range band"); each cone's covariance says how sure.
DEFAULT_MAX_RANGE_M = 40.0
#: What the shipped calibrations use instead of the thesis's corners: the bottom centre of the box
#: (the base edge nearest the camera) moved by the foot offset along the viewing ray to the cone's
#: centre. The offsets lie between half the base width and half its diagonal (small cone base
#: 228 mm: 0.114-0.161 m; large 285 mm: 0.143-0.202 m); on rendered scenes with exact boxes
#: (tests/test_foot_points.py) they cut the median error at 0-15 m from about 0.25 m to 0.03 m.
RECOMMENDED_FOOT_POINTS = dict.fromkeys(DEFAULT_FOOT_POINTS, "bottom_center")
RECOMMENDED_FOOT_OFFSET_M = {"blue": 0.15, "yellow": 0.15, "orange": 0.15, "large_orange": 0.19, "unknown": 0.15}
_KNOWN_KEYS = {
    "camera",
    "image_width",
    "image_height",
    "H_S_B",
    "T_F_S",
    "crop",
    "downscale",
    "foot_points",
    "max_range_m",
    "pixel_sigma",
    "frame_id",
    "camera_matrix",
    "dist_coeffs",
    "foot_offset_m",
    "foot_offset_from_width",
    "camera_xy_m",
    "mount_pose",
    "far_strip",
}
#: Keys of ``mount_pose`` in the YAML (the static transform of the camera uses the same names).
MOUNT_POSE_KEYS = ("x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg")


@dataclass
class Calibration:
    """One camera's calibration. Matrices are float64 numpy arrays."""

    camera: str
    image_width: int
    image_height: int
    H_S_B: np.ndarray
    T_F_S: np.ndarray
    crop: CropSpec
    foot_points: tuple[str, ...]  # rule per project class id
    max_range_m: float = DEFAULT_MAX_RANGE_M
    pixel_sigma_u: float = 1.0
    pixel_sigma_v: float = 1.0
    frame_id: str = "rear_axle"
    camera_matrix: np.ndarray | None = None
    dist_coeffs: np.ndarray | None = None
    foot_offset_m: tuple[float, ...] = (0.0,) * len(CLASS_NAMES)  # per project class id
    #: the foot offset of a class with a known base plate (CONE_SIZE_M) from each box's width instead
    #: (:meth:`cone_perception.mapping.ConeMapper.map_boxes`)
    foot_offset_from_width: bool = False
    camera_xy_m: tuple[float, float] | None = None
    mount_pose: MountPose | None = None  # needs camera_matrix; enables per-frame attitude
    far_strip: FarStripSpec | None = DEFAULT_STRIP  # the far strip's range and margins; None = off
    extra: dict[str, Any] = field(default_factory=dict)
    source: str = "<memory>"

    @property
    def has_attitude_model(self) -> bool:
        """Mount pose and camera matrix both given: ``H_F_B`` can be recomposed per body attitude."""
        return self.mount_pose is not None and self.camera_matrix is not None

    @property
    def downscale(self) -> int:
        return self.crop.downscale

    @property
    def H_F_B(self) -> np.ndarray:
        """``T_F_S @ H_S_B`` with h33 scale normalised and w > 0 at the bottom-centre pixel."""
        return fix_homography_sign(self.T_F_S @ self.H_S_B, self.ground_reference_px())

    def camera_ground_xy(self) -> np.ndarray:
        """Camera position on the ground (m, ``rear_axle``): ``camera_xy_m`` if given, else from
        ``H_F_B`` and ``camera_matrix`` (pose decomposition), else the rear-axle origin (for a foot
        offset along the viewing ray, a metre off changes the direction by a few degrees only)."""
        if self.camera_xy_m is not None:
            return np.asarray(self.camera_xy_m, dtype=np.float64)
        if self.mount_pose is not None:
            return np.array([self.mount_pose.x_m, self.mount_pose.y_m])
        if self.camera_matrix is not None:
            pose = pose_from_homography(self.H_F_B, self.camera_matrix).pose
            return np.array([pose.x_m, pose.y_m])
        return np.zeros(2)

    def strip_plan(self) -> StripPlan | None:
        """The far strip of this camera (:func:`~.strip.plan_strip`): None when ``far_strip`` is off or
        there is no ``camera_matrix`` to place it with. ConfigError naming ``far_strip`` when it would leave
        the image or lie above the horizon (:func:`load_calibration` asks at load)."""
        if self.far_strip is None or self.camera_matrix is None:
            return None
        return plan_strip(self.pinhole_camera(), self.far_strip, self.source)

    def pinhole_camera(self) -> PinholeCamera:
        """The camera model at rest (``camera_matrix``, image size, mount pose, lens) that places the far strip
        and the band; needs ``camera_matrix`` (the mount pose, if absent, from the homography)."""
        if self.camera_matrix is None:
            raise ValueError(f"{self.source}: placing rows needs camera_matrix in the calibration")
        pose = self.mount_pose or pose_from_homography(self.H_F_B, self.camera_matrix).pose
        dist = np.zeros(0) if self.dist_coeffs is None else np.asarray(self.dist_coeffs, dtype=np.float64)
        return PinholeCamera(self.camera_matrix, self.image_width, self.image_height, pose, dist)

    def ground_reference_px(self) -> tuple[float, float]:
        """A pixel known to see the ground: the bottom centre of the image."""
        return (self.image_width / 2.0, self.image_height - 1.0)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "camera": self.camera,
            "frame_id": self.frame_id,
            "image_width": int(self.image_width),
            "image_height": int(self.image_height),
            "H_S_B": _rows(self.H_S_B),
            "T_F_S": _rows(self.T_F_S),
            "crop": {"v0": self.crop.v0, "v1": self.crop.v1, "u0": self.crop.u0, "u1": self.crop.u1},
            "downscale": int(self.crop.downscale),
            "foot_points": {CLASS_NAMES[i]: r for i, r in enumerate(self.foot_points)},
            "max_range_m": float(self.max_range_m),
            "pixel_sigma": {"u": float(self.pixel_sigma_u), "v": float(self.pixel_sigma_v)},
        }
        if self.camera_matrix is not None:
            d["camera_matrix"] = _rows(self.camera_matrix)
        if self.dist_coeffs is not None:
            d["dist_coeffs"] = [float(x) for x in np.asarray(self.dist_coeffs).ravel()]
        if any(self.foot_offset_m):
            d["foot_offset_m"] = {CLASS_NAMES[i]: float(v) for i, v in enumerate(self.foot_offset_m)}
        if self.foot_offset_from_width:
            d["foot_offset_from_width"] = True
        if self.camera_xy_m is not None:
            d["camera_xy_m"] = [float(v) for v in self.camera_xy_m]
        if self.mount_pose is not None:
            d["mount_pose"] = mount_pose_to_dict(self.mount_pose)
        if self.far_strip != DEFAULT_STRIP:
            d["far_strip"] = "off" if self.far_strip is None else self.far_strip.to_dict()
        d.update(self.extra)
        return d


def mount_pose_to_dict(pose: MountPose) -> dict[str, float]:
    """:class:`MountPose` -> the YAML's ``mount_pose`` mapping (m, degrees)."""
    m = pose
    return {"x_m": float(m.x_m), "y_m": float(m.y_m), "z_m": float(m.height_m),
            "yaw_deg": float(m.yaw_deg), "pitch_deg": float(m.pitch_deg), "roll_deg": float(m.roll_deg)}


def _rows(m: np.ndarray) -> list[list[float]]:
    return [[float(x) for x in row] for row in np.asarray(m, dtype=np.float64)]


class _Fields:
    """Typed access to a YAML mapping with errors that name file and field."""

    def __init__(self, data: dict, source: str):
        self.data, self.source = data, source

    def err(self, field_name: str, msg: str) -> ConfigError:
        return ConfigError(self.source, field_name, msg)

    def get(self, key: str, default: Any = ..., where: dict | None = None, prefix: str = "") -> Any:
        d = self.data if where is None else where
        if key not in d or d[key] is None:
            if default is ...:
                raise self.err(prefix + key, "missing")
            return default
        return d[key]

    def number(self, key, default=..., where=None, prefix="", positive=False) -> float:
        v = self.get(key, default, where, prefix)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(prefix + key, f"must be a number, got {v!r}")
        if not np.isfinite(v):
            raise self.err(prefix + key, f"must be finite, got {v!r}")
        if positive and v <= 0:
            raise self.err(prefix + key, f"must be > 0, got {v!r}")
        return float(v)

    def integer(self, key, default=..., where=None, prefix="", positive=False) -> int:
        v = self.get(key, default, where, prefix)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(prefix + key, f"must be an integer, got {v!r}")
        if positive and v <= 0:
            raise self.err(prefix + key, f"must be > 0, got {v!r}")
        return int(v)

    def matrix(self, key: str, shape: tuple[int, ...], default: Any = ...) -> np.ndarray | None:
        v = self.get(key, default)
        if v is None:
            return None
        try:
            m = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.err(key, f"must be a {shape[0]}x{shape[1]} list of rows of numbers") from None
        if m.shape != shape:
            raise self.err(key, f"must have shape {shape}, got {m.shape}")
        if not np.all(np.isfinite(m)):
            raise self.err(key, "has non-finite values (nan/inf)")
        return m


def resolve_calibration_path(name_or_path: str | os.PathLike) -> Path:
    """A calibration file path, or a camera name looked up in the shipped ``calib/``."""
    return resolve_in(calib_dir(), name_or_path, (".yaml", ".yml"))


def load_calibration(name_or_path: str | os.PathLike = DEFAULT_CAMERA) -> Calibration:
    """Load and validate a calibration YAML (path or shipped camera name)."""
    path = resolve_calibration_path(name_or_path)
    src = str(path)
    if not path.is_file():
        raise ConfigError(src, None, "calibration file not found")
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(src, None, f"cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(src, None, "is not UTF-8 text (binary file?)") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ConfigError(src, None, f"not valid YAML: {e}") from None
    if not isinstance(data, dict):
        raise ConfigError(src, None, "must be a YAML mapping of calibration fields")
    return calibration_from_dict(data, src)


def calibration_from_dict(data: dict, source: str = "<memory>") -> Calibration:
    """Validate a calibration mapping (as loaded from YAML)."""
    f = _Fields(data, source)
    camera = str(f.get("camera"))
    width = f.integer("image_width", positive=True)
    height = f.integer("image_height", positive=True)
    for key, v in (("image_width", width), ("image_height", height)):
        if v > MAX_IMAGE_SIDE_PX:
            raise f.err(key, f"must be at most {MAX_IMAGE_SIDE_PX} px, got {v}")

    H_S_B = f.matrix("H_S_B", (3, 3))
    if abs(np.linalg.det(H_S_B)) < 1e-12 * max(1.0, np.abs(H_S_B).max() ** 3) or np.linalg.cond(H_S_B) > 1e15:
        raise f.err("H_S_B", "is singular (not invertible)")
    T_F_S = f.matrix("T_F_S", (3, 3))
    if not np.allclose(T_F_S[2], [0.0, 0.0, 1.0], atol=1e-9):
        raise f.err("T_F_S", f"last row must be [0, 0, 1] (planar rigid transform), got {T_F_S[2].tolist()}")
    R = T_F_S[:2, :2]
    if not np.allclose(R @ R.T, np.eye(2), atol=1e-6) or np.linalg.det(R) < 0:
        raise f.err("T_F_S", "upper-left 2x2 must be a rotation (orthonormal, det +1)")

    crop_d = f.get("crop")
    if not isinstance(crop_d, dict):
        raise f.err("crop", "must be a mapping with v0, v1 (and optional u0, u1)")
    crop = CropSpec(
        v0=f.integer("v0", where=crop_d, prefix="crop."),
        v1=f.integer("v1", where=crop_d, prefix="crop."),
        u0=f.integer("u0", 0, where=crop_d, prefix="crop."),
        u1=f.integer("u1", width, where=crop_d, prefix="crop."),
        downscale=f.integer("downscale", 1, positive=True),
    )
    crop.validate(width, height, source)

    fp = dict(DEFAULT_FOOT_POINTS)
    fp_d = f.get("foot_points", {})
    if not isinstance(fp_d, dict):
        raise f.err("foot_points", "must be a mapping class name -> rule")
    for name, rule in fp_d.items():
        if name not in CLASS_NAMES:
            raise f.err(f"foot_points.{name}", f"unknown class name; known: {', '.join(CLASS_NAMES)}")
        if rule not in FOOT_RULES:
            raise f.err(f"foot_points.{name}", f"unknown rule {rule!r}; known: {', '.join(FOOT_RULES)}")
        fp[name] = rule

    offsets = dict.fromkeys(CLASS_NAMES, 0.0)
    off_d = f.get("foot_offset_m", {})
    if not isinstance(off_d, dict):
        raise f.err("foot_offset_m", "must be a mapping class name -> metres")
    for name in off_d:
        if name not in CLASS_NAMES:
            raise f.err(f"foot_offset_m.{name}", f"unknown class name; known: {', '.join(CLASS_NAMES)}")
        offsets[name] = f.number(name, where=off_d, prefix="foot_offset_m.")
        if not 0.0 <= offsets[name] <= 0.5:
            raise f.err(f"foot_offset_m.{name}", f"must be within 0..0.5 m, got {offsets[name]}")
    from_width = f.get("foot_offset_from_width", False)
    if not isinstance(from_width, bool):
        raise f.err("foot_offset_from_width", f"must be true or false, got {from_width!r}")
    cam_xy = f.get("camera_xy_m", None)
    if cam_xy is not None:
        try:
            cam_xy = tuple(float(v) for v in cam_xy)
        except (TypeError, ValueError):
            raise f.err("camera_xy_m", "must be [x, y] in metres") from None
        if len(cam_xy) != 2 or not all(np.isfinite(cam_xy)):
            raise f.err("camera_xy_m", f"must be two finite numbers [x, y], got {cam_xy}")

    sigma = f.get("pixel_sigma", {"u": 1.0, "v": 1.0})
    if not isinstance(sigma, dict):
        raise f.err("pixel_sigma", "must be a mapping with u and v (pixels)")
    K = f.matrix("camera_matrix", (3, 3), None)
    dist = f.get("dist_coeffs", None)
    if dist is not None:
        try:
            dist = np.asarray(dist, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise f.err("dist_coeffs", "must be a list of numbers") from None
        if dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
            raise f.err("dist_coeffs", f"must be 4, 5, 8, 12 or 14 finite numbers (OpenCV model), got {dist.size}")
        if K is None:
            raise f.err("dist_coeffs", "needs camera_matrix too")

    mount_pose = None
    mp = f.get("mount_pose", None)
    if mp is not None:
        if not isinstance(mp, dict):
            raise f.err("mount_pose", f"must be a mapping with {', '.join(MOUNT_POSE_KEYS)}")
        for k in mp:
            if k not in MOUNT_POSE_KEYS:
                raise f.err(f"mount_pose.{k}", f"unknown key; known: {', '.join(MOUNT_POSE_KEYS)}")
        v = {k: f.number(k, 0.0 if k.endswith("_deg") or k == "y_m" else ..., where=mp, prefix="mount_pose.")
             for k in MOUNT_POSE_KEYS}
        if v["z_m"] <= 0:
            raise f.err("mount_pose.z_m", f"camera height must be > 0 m, got {v['z_m']}")
        if not -90.0 < v["pitch_deg"] < 90.0:
            raise f.err("mount_pose.pitch_deg", f"must be within -90..90 degrees, got {v['pitch_deg']}")
        mount_pose = MountPose(v["x_m"], v["y_m"], v["z_m"], v["pitch_deg"], v["roll_deg"], v["yaw_deg"])

    calib = Calibration(
        camera=camera,
        image_width=width,
        image_height=height,
        H_S_B=H_S_B,
        T_F_S=T_F_S,
        crop=crop,
        foot_points=tuple(fp[n] for n in CLASS_NAMES),
        max_range_m=f.number("max_range_m", DEFAULT_MAX_RANGE_M, positive=True),
        pixel_sigma_u=f.number("u", 1.0, where=sigma, prefix="pixel_sigma.", positive=True),
        pixel_sigma_v=f.number("v", 1.0, where=sigma, prefix="pixel_sigma.", positive=True),
        frame_id=str(f.get("frame_id", "rear_axle")),
        camera_matrix=K,
        dist_coeffs=dist,
        foot_offset_m=tuple(offsets[n] for n in CLASS_NAMES),
        foot_offset_from_width=from_width,
        camera_xy_m=cam_xy,
        mount_pose=mount_pose,
        far_strip=strip_spec_from_yaml(data.get("far_strip"), f.err),
        extra={k: v for k, v in data.items() if k not in _KNOWN_KEYS},
        source=source,
    )
    try:
        calib.H_F_B
    except ValueError as e:
        raise f.err("H_S_B", str(e)) from None
    if calib.has_attitude_model:
        bad = mount_pose_disagreement(calib.H_F_B, K, mount_pose, width, height)
        if not bad <= MOUNT_POSE_TOLERANCE:
            raise f.err("mount_pose", f"disagrees with the file's own H_F_B (H_S_B, T_F_S, camera_matrix) by "
                        f"{bad * 100:.1f} % of range at {MOUNT_POSE_CHECK_RANGE_M:g} m (at most "
                        f"{MOUNT_POSE_TOLERANCE * 100:g} %): wrong pose, or H calibrated for another mount")
    calib.strip_plan()  # a far strip outside the image or above the horizon: refused here, naming far_strip
    return calib


def save_calibration(calib: Calibration, path: str | os.PathLike, header: str | None = None) -> Path:
    """Write ``calib`` as YAML (matrices one row per line). Returns the path."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(str(path), None, f"cannot create directory: {e.strerror}") from None

    class _Dumper(yaml.SafeDumper):
        pass

    def _list(dumper, data):
        flow = all(not isinstance(x, (list, dict)) for x in data)
        return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)

    _Dumper.add_representer(list, _list)
    text = yaml.dump(calib.to_dict(), Dumper=_Dumper, sort_keys=False, default_flow_style=False)
    try:
        path.write_text((f"# {header}\n" if header else "") + text, encoding="utf-8")
    except OSError as e:
        raise ConfigError(str(path), None, f"cannot write: {e.strerror}") from None
    return path
