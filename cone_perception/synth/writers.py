"""What ``cone-perception synth`` writes: datasets, rosbags, contact sheets, the calibration
(the settings: :class:`~.config.SynthConfig`; the mapping check: :mod:`.mapcheck`).

* Dataset (``DIR``): ``images/{train,val}/NNNNNN.jpg``, ``labels/{train,val}/NNNNNN.txt``
  (YOLO ``class cx cy w h`` normalised, project class ids), ``data.yaml``,
  ``gt.jsonl`` (one line per image: size, track, pose, every cone with visible
  pixels), ``calib.yaml``. Train / val are split by track (never frames of one
  track on both sides).
* Bag: rosbag2 (MCAP) with ``/camera/image_raw`` (``yuv422_yuy2``) or
  ``/camera/image_raw/compressed`` (JPEG), and ``/cones_gt`` (PointCloud2 in the
  ``/cones`` schema, frame ``rear_axle``, same stamps, every cone with a visible
  pixel, ``score`` = its visible fraction), ``/attitude_gt`` (Vector3Stamped: the exact
  camera attitude against the ground, x = roll, y = pitch in radians, as ``cones/attitude``)
  ``/imu`` (sensor_msgs/Imu, see :mod:`.motion`) and ``/odom`` (nav_msgs/Odometry at 50 Hz, the true
  body twist with noise and bias, see :mod:`.odometry`); beside it
  ``<bag>_calib.yaml`` and ``<bag>_gt.jsonl``.

YOLO labels hold only cones whose box is at least :data:`MIN_LABEL_BOX_PX`
pixels wide and high and whose visible fraction is at least
:data:`MIN_LABEL_VISIBLE`; ``gt.jsonl`` keeps every cone with a visible pixel.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np
import yaml
from tqdm import tqdm

from ..classes import CLASS_BGR, CLASS_NAMES
from ..data.bagio import (
    COMPRESSED_IMAGE, IMAGE, IMU, ODOMETRY, POINTCLOUD2, VECTOR3_STAMPED, BagWriter, Imu, Odometry, Point, PointCloud2,
    PointField, Pose, PoseWithCovariance, Quaternion, Twist, TwistWithCovariance, Vector3, Vector3Stamped,
    check_new_output, compressed_msg_from_bgr, ensure_writable_dir, header, image_msg_from_bgr,
)
from ..errors import ConfigError
from ..records import CONE_DTYPE, to_pointcloud2
from ..vis import frame_strip, outlined_text
from .config import SynthConfig
from .motion import (
    IMU_ACCEL_NOISE, IMU_ANGLE_NOISE_DEG, IMU_RATE_NOISE_DPS, constant_speed_drive, drive_motion, imu_samples,
)
from .odometry import ODOM_V_NOISE, ODOM_VY_NOISE, ODOM_W_NOISE, OdomSample, odometry_samples
from .render import ConeTruth
from .scene import CarPose, drive_poses, jitter_series, random_pose
from .track import TRACK_KINDS, Track, make_track

MIN_LABEL_BOX_PX = 4.0
MIN_LABEL_VISIBLE = 0.3
START_STAMP_NS = 1_700_000_000 * 1_000_000_000
IMAGE_TOPIC = "/camera/image_raw"
COMPRESSED_TOPIC = "/camera/image_raw/compressed"
GT_TOPIC = "/cones_gt"
ATTITUDE_GT_TOPIC = "/attitude_gt"
IMU_TOPIC = "/imu"
ODOM_TOPIC = "/odom"
CAMERA_FRAME = "camera"

log = logging.getLogger(__name__)


def check_writable_dir(path: Path, what: str) -> None:
    """Raise :class:`ConfigError` unless ``path`` is (or can be made) an empty writable directory."""
    if path.exists() and not path.is_dir():
        raise ConfigError(str(path), None, f"{what} output exists and is not a directory")
    if path.is_dir() and any(path.iterdir()):
        raise ConfigError(str(path), None, f"{what} output directory is not empty; choose a new one")
    ensure_writable_dir(path)


def yolo_lines(truths: list[ConeTruth], width: int, height: int) -> list[str]:
    """YOLO label lines ``class cx cy w h`` (normalised) of the cones worth labelling."""
    out = []
    for t in truths:
        u1, v1, u2, v2 = t.box
        if u2 - u1 < MIN_LABEL_BOX_PX or v2 - v1 < MIN_LABEL_BOX_PX or t.visible_fraction < MIN_LABEL_VISIBLE:
            continue
        out.append(
            f"{t.class_id} {(u1 + u2) / 2 / width:.6f} {(v1 + v2) / 2 / height:.6f} {(u2 - u1) / width:.6f} {(v2 - v1) / height:.6f}"
        )
    return out


def gt_record(image: str, cfg: SynthConfig, track: Track, pose: CarPose, truths: list[ConeTruth]) -> dict:
    return {
        "image": image,
        "width": cfg.width,
        "height": cfg.height,
        "track": {"kind": track.kind, "seed": track.seed},
        "pose": pose.to_dict(),
        "camera": cfg.camera_record(),
        "cones": [t.to_dict() for t in truths],
    }


def truths_to_records(truths: list[ConeTruth]) -> np.ndarray:
    """Ground truth -> :data:`CONE_DTYPE` records (``rear_axle`` m, ``score`` = visible fraction, zero covariance)."""
    rec = np.zeros(len(truths), dtype=CONE_DTYPE)
    rec["x"] = [t.x_m for t in truths]
    rec["y"] = [t.y_m for t in truths]
    rec["class_id"] = [t.class_id for t in truths]
    rec["score"] = [t.visible_fraction for t in truths]
    return rec


def _progress(total: int, desc: str, enabled: bool):
    return tqdm(total=total, desc=desc, unit="frame", disable=not enabled)


def write_dataset(
    cfg: SynthConfig, n: int, out: Path, frames_per_track: int = 20, val_frac: float = 0.1, progress: bool = True
) -> dict:
    """Render ``n`` frames into a YOLO dataset directory; returns counts."""
    if n <= 0:
        raise ConfigError("--n", None, f"must be > 0, got {n}")
    if frames_per_track <= 0:
        raise ConfigError("--frames-per-track", None, f"must be > 0, got {frames_per_track}")
    if not 0.0 <= val_frac < 1.0:
        raise ConfigError("--val-frac", None, f"must be within 0..1, got {val_frac}")
    cfg.validate()
    out = Path(out)
    check_writable_dir(out, "dataset")
    n_tracks = -(-n // frames_per_track)
    n_val = int(round(n_tracks * val_frac))
    if val_frac > 0 and n_val == 0 and n_tracks >= 2:
        n_val = 1
    n_val = min(n_val, n_tracks - 1)  # whole tracks (frames of one track look alike); train keeps one at least
    if val_frac > 0 and n_val == 0:
        log.warning("synth dataset: %d frames make one track (--frames-per-track %d): no val split (data.yaml has no "
                    "val:, 'train' then trains without validation); for one, give --n above --frames-per-track",
                    n, frames_per_track)
    splits = ("train", "val") if n_val else ("train",)
    for split in splits:
        (out / "images" / split).mkdir(parents=True, exist_ok=True)
        (out / "labels" / split).mkdir(parents=True, exist_ok=True)
    cfg.save_calibration(out / "calib.yaml")
    (out / "data.yaml").write_text(
        yaml.safe_dump(
            {"path": str(out.resolve()), "train": "images/train", **({"val": "images/val"} if n_val else {}),
             "nc": len(CLASS_NAMES), "names": list(CLASS_NAMES)},
            sort_keys=False,
        ),
        encoding="utf-8",
    )
    renderer = cfg.renderer()
    frame_cfg = cfg
    rng = np.random.default_rng(cfg.seed)
    counts = {"train": 0, "val": 0, "labels": 0, "cones": 0}
    with open(out / "gt.jsonl", "w", encoding="utf-8") as gt, _progress(n, "synth dataset", progress) as bar:
        for k in range(n):
            t = k // frames_per_track
            if k % frames_per_track == 0:
                track = cfg.track(t, rng)
                if cfg.vary_mount:
                    frame_cfg = cfg.varied(rng)
                    renderer = frame_cfg.renderer()
                look = renderer.new_look(rng)
            split = "val" if t >= n_tracks - n_val else "train"
            pose = random_pose(track, rng, cfg.jitter)
            img, truths = renderer.render(track, pose, look, rng)
            name = f"{k:06d}"
            rel = f"images/{split}/{name}.jpg"
            cv2.imwrite(str(out / rel), img, [cv2.IMWRITE_JPEG_QUALITY, 93])
            lines = yolo_lines(truths, cfg.width, cfg.height)
            (out / "labels" / split / f"{name}.txt").write_text("".join(x + "\n" for x in lines), encoding="utf-8")
            gt.write(json.dumps(gt_record(rel, frame_cfg, track, pose, truths)) + "\n")
            counts[split] += 1
            counts["labels"] += len(lines)
            counts["cones"] += len(truths)
            bar.update(1)
    return counts


def bag_side_paths(bag: Path) -> tuple[Path, Path]:
    """(calibration YAML, gt.jsonl) written beside a bag directory."""
    return bag.parent / f"{bag.name}_calib.yaml", bag.parent / f"{bag.name}_gt.jsonl"


def bag_scene(cfg: SynthConfig, fps: float, speed_mps: float, track_kind: str):
    """The scene a bag of ``cfg`` draws before its first frame: ``(rng, track, renderer, look)``, the generator then
    at the state the drive goes on from (:func:`write_scene_bag`; the validation suite reads a seed's look, e.g. its
    sun, from it without rendering)."""
    rng = np.random.default_rng(cfg.seed)
    track = make_track(track_kind, int(rng.integers(0, 2**31)), cfg.missing_frac, cfg.stray, cfg.knocked_frac)
    renderer = cfg.renderer(jpeg_prob=0.0, speed_mps=max(speed_mps, 1e-3), fps=fps, steady_photometric=True)
    return rng, track, renderer, renderer.new_look(rng)


def write_scene_bag(
    cfg: SynthConfig,
    seconds: float,
    fps: float,
    out: Path,
    compressed: bool = False,
    speed_mps: float = 8.0,
    track_kind: str = "autocross",
    progress: bool = True,
    stand_s: float = 0.0,
) -> dict:
    """Drive a track at ``speed_mps`` for ``seconds`` and record a rosbag2 (MCAP); returns message counts.
    ``stand_s``: the bag begins with that many seconds of ``/imu`` alone, the car standing still before
    the drive (for ``cone-perception imu-rest``)."""
    if not fps > 0:
        raise ConfigError("--fps", None, f"must be > 0, got {fps}")
    if not seconds > 0:
        raise ConfigError("--seconds", None, f"must be > 0, got {seconds}")
    if not 0 <= stand_s <= 60:
        raise ConfigError("--stand", None, f"must be within 0-60 s, got {stand_s}")
    if speed_mps < 0:
        raise ConfigError("--speed", None, f"must be >= 0 m/s, got {speed_mps}")
    if track_kind not in TRACK_KINDS:
        raise ConfigError("--track", None, f"unknown track kind {track_kind!r}; known: {', '.join(TRACK_KINDS)}")
    cfg.validate()
    out = Path(out)
    check_new_output(out, "bag")
    calib_path, gt_path = bag_side_paths(out)
    for p in (calib_path, gt_path):
        if p.exists():
            raise ConfigError(str(p), None, "exists; remove it or choose another bag path")
    n = max(int(round(seconds * fps)), 1)
    rng, track, renderer, look = bag_scene(cfg, fps, speed_mps, track_kind)
    poses, drive = _drive(cfg, track, n, fps, speed_mps, rng)
    n_stand = int(round(stand_s * fps))
    still, imu = imu_samples(drive, np.array([p.yaw_rad for p in poses]), fps, np.random.default_rng([cfg.seed, 15]), n_stand)
    odom = odometry_samples(np.array([(p.x_m, p.y_m, p.yaw_rad) for p in poses]), fps, START_STAMP_NS,
                            np.random.default_rng([cfg.seed, 17]))
    next_odom = 0
    img_topic = COMPRESSED_TOPIC if compressed else IMAGE_TOPIC
    topics = {img_topic: COMPRESSED_IMAGE if compressed else IMAGE, GT_TOPIC: POINTCLOUD2,
              ATTITUDE_GT_TOPIC: VECTOR3_STAMPED, IMU_TOPIC: IMU, ODOM_TOPIC: ODOMETRY}
    cfg.save_calibration(calib_path)
    with BagWriter(out, topics) as bag, open(gt_path, "w", encoding="utf-8") as gt, _progress(n, "synth bag", progress) as bar:
        for j, s in enumerate(still):
            stamp = START_STAMP_NS - int(round((n_stand - j) * 1e9 / fps))
            bag.write(IMU_TOPIC, stamp, _imu_msg(s, stamp))
        for i, pose in enumerate(poses):
            stamp = START_STAMP_NS + int(round(i * 1e9 / fps))
            while next_odom < len(odom) and odom[next_odom].stamp_ns <= stamp:
                bag.write(ODOM_TOPIC, odom[next_odom].stamp_ns, _odom_msg(odom[next_odom]))
                next_odom += 1
            img, truths = renderer.render(track, pose, look, rng)
            msg = compressed_msg_from_bgr(img, stamp, CAMERA_FRAME) if compressed else image_msg_from_bgr(img, stamp, CAMERA_FRAME)
            bag.write(img_topic, stamp, msg)
            cloud = to_pointcloud2(truths_to_records(truths), header(stamp, "rear_axle"), PointCloud2, PointField)
            bag.write(GT_TOPIC, stamp, cloud)
            bag.write(ATTITUDE_GT_TOPIC, stamp, Vector3Stamped(header=header(stamp, "rear_axle"), vector=Vector3(
                x=float(np.radians(pose.roll_deg)), y=float(np.radians(pose.pitch_deg)), z=0.0)))
            bag.write(IMU_TOPIC, stamp, _imu_msg(imu[i], stamp))
            rec = gt_record(f"{stamp}", cfg, track, pose, truths)
            rec["stamp_ns"] = stamp
            gt.write(json.dumps(rec) + "\n")
            bar.update(1)
        counts = dict(bag.counts)
    return counts


def _drive(cfg: SynthConfig, track: Track, n: int, fps: float, speed_mps: float, rng: np.random.Generator):
    """Poses and motion of a bag's drive. Without ``car_motion`` the poses are exactly those of
    earlier versions (same seed, same bag); the car motion draws from its own generator."""
    if not cfg.car_motion:
        poses = drive_poses(track, n, fps, speed_mps, rng, cfg.jitter)
        return poses, constant_speed_drive(poses, speed_mps, fps)
    jit = jitter_series(n, fps, rng) if cfg.jitter else np.zeros((n, 2))
    drive = drive_motion(track, n, fps, speed_mps, np.random.default_rng([cfg.seed, 16]), jit)
    poses = []
    for i in range(n):
        x, y, yaw = track.pose_at(float(drive.s_m[i]))
        poses.append(CarPose(x, y, yaw, float(drive.pitch_deg[i]), float(drive.roll_deg[i])))
    return poses, drive


def _odom_msg(o: OdomSample):
    x, y, yaw = o.pose
    twist_cov = np.diag([ODOM_V_NOISE**2, ODOM_VY_NOISE**2, 1e6, 1e6, 1e6, ODOM_W_NOISE**2]).ravel()
    return Odometry(
        header=header(o.stamp_ns, "odom"),
        child_frame_id="rear_axle",
        pose=PoseWithCovariance(pose=Pose(position=Point(x=x, y=y, z=0.0), orientation=Quaternion(
            x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2)))), covariance=np.zeros(36)),
        twist=TwistWithCovariance(twist=Twist(linear=Vector3(x=o.twist[0], y=o.twist[1], z=0.0),
                                              angular=Vector3(x=0.0, y=0.0, z=o.twist[2])), covariance=twist_cov),
    )


def _imu_msg(s, stamp: int):
    cov = np.zeros(9)
    q = Quaternion(x=float(s.quat_xyzw[0]), y=float(s.quat_xyzw[1]), z=float(s.quat_xyzw[2]), w=float(s.quat_xyzw[3]))
    return Imu(
        header=header(stamp, "imu"),
        orientation=q,
        orientation_covariance=np.diag([np.radians(IMU_ANGLE_NOISE_DEG) ** 2] * 3).ravel(),
        angular_velocity=Vector3(x=float(s.rate[0]), y=float(s.rate[1]), z=float(s.rate[2])),
        angular_velocity_covariance=np.diag([np.radians(IMU_RATE_NOISE_DPS) ** 2] * 3).ravel(),
        linear_acceleration=Vector3(x=float(s.accel[0]), y=float(s.accel[1]), z=float(s.accel[2])),
        linear_acceleration_covariance=cov + np.diag([IMU_ACCEL_NOISE**2] * 3).ravel(),
    )


def draw_truths(img: np.ndarray, truths: list[ConeTruth], thickness: int = 2) -> np.ndarray:
    """Boxes in class colours; labelled cones solid, unlabelled (too small / hidden) thin."""
    for t in truths:
        u1, v1, u2, v2 = (int(round(x)) for x in t.box)
        labelled = (u2 - u1 >= MIN_LABEL_BOX_PX and v2 - v1 >= MIN_LABEL_BOX_PX and t.visible_fraction >= MIN_LABEL_VISIBLE)
        cv2.rectangle(img, (u1, v1), (u2, v2), CLASS_BGR[t.class_id], thickness if labelled else 1)
        if labelled and v2 - v1 >= 14:
            outlined_text(img, f"{t.distance_m:.1f}m", (u1, max(v1 - 4, 10)), CLASS_BGR[t.class_id], 0.5)
    return img


def write_preview(cfg: SynthConfig, out: Path, n: int = 8, cols: int = 2, thumb_w: int = 960) -> Path:
    """Contact sheet PNG of ``n`` frames (new track and look each) with ground-truth boxes."""
    if n <= 0:
        raise ConfigError("--n", None, f"must be > 0, got {n}")
    cfg.validate()
    out = Path(out)
    if out.suffix.lower() != ".png":
        raise ConfigError(str(out), None, "preview output must be a .png file")
    ensure_writable_dir(out.parent)
    renderer = cfg.renderer()
    rng = np.random.default_rng(cfg.seed)
    thumbs = []
    for k in range(n):
        track = cfg.track(k, rng)
        look = renderer.new_look(rng)
        img, truths = renderer.render(track, random_pose(track, rng, cfg.jitter), look, rng)
        img = draw_truths(img, truths, thickness=max(cfg.width // 640, 1))

        th = int(round(thumb_w * cfg.height / cfg.width))
        thumb = cv2.resize(img, (thumb_w, th), interpolation=cv2.INTER_AREA)
        outlined_text(thumb, f"{track.kind} seed {track.seed}", (8, 24), (255, 255, 255), 0.7, 2)
        thumbs.append(thumb)

    sheet = frame_strip(thumbs, width=thumb_w, cols=cols)
    if not cv2.imwrite(str(out), sheet):
        raise ConfigError(str(out), None, "cannot write PNG")
    return out
