"""The far strip placed from the calibration (geometry/strip.py): its rows, its bad calibrations, and how
the pipeline moves it each frame with the attitude (clamped and counted), cutting cones at the moved rows."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from cone_perception.crop import CropSpec
from cone_perception.detector.farband import FarBand, far_rows_for
from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import calibration_from_dict, load_calibration, save_calibration
from cone_perception.geometry.camera import MountPose, PinholeCamera
from cone_perception.geometry.strip import FarStripSpec, needed_rows, plan_strip, tilted
from cone_perception.records import boxes_from_arrays
from cone_perception.resources import calib_dir

CALIB = load_calibration("example_mainhoop")


def _camera(pose: MountPose | None = None, hfov_deg: float = 90.0) -> PinholeCamera:
    from cone_perception.geometry.camera import default_intrinsics

    return PinholeCamera(default_intrinsics(1920, 1080, hfov_deg), 1920, 1080, pose or CALIB.mount_pose)


def _points_in_view(cam: PinholeCamera, d: float, z: float, mount: MountPose) -> np.ndarray:
    """Image rows of points ``d`` m ahead of the camera at height ``z`` across the view (what the strip must hold)."""
    s = np.linspace(-2.0 * d, 2.0 * d, 801)
    uv, depth = cam.project(np.column_stack([np.full_like(s, mount.x_m + d), mount.y_m + s, np.full_like(s, z)]))
    ok = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1)
    return uv[ok, 1]


def test_example_strip_holds_the_far_tops_and_near_feet_in_96_rows():
    """example_mainhoop (1920x1080, fy 960, 1.2 m, pitch 10 deg): the strip is 96 rows (a multiple of 32, half
    the hand-set 192), centred on the rows from a large cone's top 40 m ahead (about row 388) to a cone's foot
    15 m ahead (about 449) with the attitude margins around them; the horizon (row 371) is above its cones."""
    plan = CALIB.strip_plan()
    assert plan.height == 96 and plan.rows == (370, 466)
    top, bottom, horizon = needed_rows(plan.camera, 15.0, 40.0)
    assert top == pytest.approx(540 - 960 * np.tan(np.radians(10) - np.arctan(0.695 / 40)), abs=0.5)
    assert bottom == pytest.approx(540 - 960 * np.tan(np.radians(10) - np.arctan(1.2 / 15)), abs=0.5)
    assert horizon == pytest.approx(370.7, abs=0.2)
    rows = np.concatenate([_points_in_view(plan.camera, 40.0, 0.505, CALIB.mount_pose),
                           _points_in_view(plan.camera, 15.0, 0.0, CALIB.mount_pose)])
    assert rows.min() >= plan.rows[0] + 8 and rows.max() <= plan.rows[1] - 8  # the margins' room left
    assert far_rows_for(None, CALIB).crop == CropSpec(370, 466, 0, 1920, 1)


@pytest.mark.parametrize("pitch, roll, d_pitch", [(0.0, 0.5, 0.5), (2.0, -0.5, -0.5), (-2.0, 0.4, 0.5),
                                                  (1.5, 0.0, -0.5), (-3.0, 0.5, 0.5)])
def test_moved_strip_holds_the_cones_when_the_attitude_it_follows_is_off_by_the_margins(pitch, roll, d_pitch):
    """The body tilted by (pitch, roll): the strip placed for an attitude off by up to the margins (0.5 deg pitch,
    the strip never tilts: the roll is in the margin) still holds every far top and near foot in view (to within
    a pixel: the height is sized at the calibration's attitude, and the rows are whole)."""
    plan = CALIB.strip_plan()
    top, clamped = plan.top_for(pitch + d_pitch, 0.0)
    assert not clamped
    cam = PinholeCamera(plan.camera.K, 1920, 1080, tilted(CALIB.mount_pose, pitch, roll))
    m = CALIB.mount_pose
    rows = np.concatenate([_points_in_view(cam, 40.0, 0.505, m), _points_in_view(cam, 15.0, 0.0, m)])
    assert top - 1 <= rows.min() and rows.max() <= top + plan.height + 1, (top, rows.min(), rows.max())
    # it did move: one degree of pitch (nose down) is about 17 rows up here
    assert plan.top_for(pitch, 0.0)[0] - plan.top_for(pitch + 1.0, 0.0)[0] == pytest.approx(17, abs=2)


def test_strip_leaving_the_image_is_clamped_and_says_so():
    plan = CALIB.strip_plan()
    assert plan.top_for(0.0, 0.0) == (370, False)
    assert plan.top_for(30.0, 0.0) == (0, True)  # nose far down: the far rows move up, out of the image
    assert plan.top_for(-40.0, 0.0) == (1080 - 96, True)


def _calib_dict(pose: MountPose, hfov_deg: float = 90.0, **extra) -> dict:
    """The example calibration with another exact mount (H from the pose)."""
    cam = _camera(pose, hfov_deg)
    d = yaml.safe_load((calib_dir() / "example_mainhoop.yaml").read_text())
    d["H_S_B"] = cam.H_F_B().tolist()
    d["T_F_S"] = np.eye(3).tolist()
    d["camera_matrix"] = cam.K.tolist()
    d["mount_pose"] = {"x_m": pose.x_m, "y_m": pose.y_m, "z_m": pose.height_m, "yaw_deg": pose.yaw_deg,
                       "pitch_deg": pose.pitch_deg, "roll_deg": pose.roll_deg}
    d["crop"] = {"v0": 0, "v1": 1080}
    d.update(extra)
    return d


@pytest.mark.parametrize("pose, strip, why", [
    (MountPose(0.5, 0.0, 1.2, 35.0, 0.0, 0.0), None, "rows -?[0-9]+--?[0-9]+ .*outside the 1920x1080 image"),  # looks down
    (CALIB.mount_pose, {"near_m": 1.0}, "outside the 1920x1080 image"),  # feet 1 m ahead: below the image
    (MountPose(0.5, 0.0, 1.2, -20.0, 0.0, 0.0), {"near_m": 3.0}, "outside the 1920x1080 image"),  # looks up
])
def test_calibration_whose_strip_leaves_the_image_is_refused_at_load(tmp_path, pose, strip, why):
    d = _calib_dict(pose, **({"far_strip": strip} if strip else {}))
    path = tmp_path / "cam.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError, match=f"cam.yaml: far_strip: .*{why}"):
        load_calibration(path)
    d["far_strip"] = "off"  # the same camera without a strip loads
    assert calibration_from_dict(d).strip_plan() is None


def test_strip_above_the_horizon_is_refused():
    """A camera model whose near cones' feet are not below the horizon (here: mounted upside down, the ground
    at the image's top) gives no strip: refused naming the field."""
    cam = _camera(MountPose(0.5, 0.0, 1.2, 10.0, 180.0, 0.0))
    with pytest.raises(ConfigError, match="cam.yaml: far_strip: .*above the horizon"):
        plan_strip(cam, source="cam.yaml")


@pytest.mark.parametrize("value, field, why", [
    ({"near_m": 40.0, "far_m": 15.0}, "far_strip", "0 < near_m < far_m"),
    ({"far_m": "far"}, "far_strip.far_m", "finite number"),
    ({"near": 10}, "far_strip.near", "unknown key"),
    ({"roll_margin_deg": 20}, "far_strip.roll_margin_deg", "0..10 degrees"),
    ("sometimes", "far_strip", "must be off or a mapping"),
])
def test_bad_far_strip_fields_are_refused_naming_the_field(value, field, why):
    with pytest.raises(ConfigError, match=f"{field}: .*{why}"):
        calibration_from_dict(_calib_dict(CALIB.mount_pose, far_strip=value), "cam.yaml")


def test_far_strip_settings_change_the_rows_and_survive_a_save(tmp_path):
    """A longer range or wider margins make a taller strip; the setting is saved and loaded back; off stays off."""
    c = calibration_from_dict(_calib_dict(CALIB.mount_pose, far_strip={"near_m": 12.0, "roll_margin_deg": 1.0}))
    plan = c.strip_plan()
    assert plan.height > 96 and plan.height % 32 == 0 and plan.rows[1] > 466
    again = load_calibration(save_calibration(c, tmp_path / "c.yaml"))
    assert again.far_strip == FarStripSpec(near_m=12.0, roll_margin_deg=1.0)
    assert again.strip_plan().rows == plan.rows
    c.far_strip = None
    assert load_calibration(save_calibration(c, tmp_path / "off.yaml")).far_strip is None
    assert "off" in far_rows_for("auto", again.__class__(**{**again.__dict__, "far_strip": None})).what


def test_a_calibration_without_camera_matrix_has_no_strip_and_says_why():
    d = yaml.safe_load((calib_dir() / "example_mainhoop.yaml").read_text())
    for k in ("camera_matrix", "mount_pose"):
        del d[k]
    fr = far_rows_for("auto", calibration_from_dict(d, "nocam.yaml"), "--far-rows")
    assert fr.crop is None and "nocam.yaml has no camera_matrix" in fr.what
    assert far_rows_for("384,576", calibration_from_dict(d)).crop == CropSpec(384, 576, 0, 1920, 1)


def test_strip_plan_of_other_lenses_and_mounts():
    """Another camera needs no hand-set rows: a wider lens or a lower camera needs fewer rows, a longer lens more."""
    base = CALIB.strip_plan()
    wide, long = plan_strip(_camera(hfov_deg=110.0)), plan_strip(_camera(hfov_deg=50.0))
    low = plan_strip(_camera(MountPose(0.5, 0.0, 0.8, 10.0, 0.0, 0.0)))
    assert all(p.height % 32 == 0 for p in (wide, long, low))
    assert wide.height <= base.height and low.height <= base.height < long.height

    def span(p):
        t, b, _ = needed_rows(p.camera, 15, 40)
        return b - t
    assert span(wide) < span(base) and span(low) < span(base) < span(long)
    assert span(base) == pytest.approx(61, abs=1)


class _Recorder:
    """A detector double: records the crops it is given and returns one box per call at given full-image rows."""

    def __init__(self, box_rows=None):
        self.crops, self.shapes, self.pixels, self.box_rows = [], [], [], box_rows
        self.timing = {"preprocess_ms": 0.0, "forward_ms": 0.0, "postprocess_ms": 0.0}

    def detect(self, bgr, crop):
        self.crops.append(crop)
        self.shapes.append(bgr.shape)
        self.pixels.append([int(bgr[0, 0, 0]), int(bgr[-1, 0, 0])])
        rows = self.box_rows(crop) if self.box_rows else []
        a = np.array([[900, v1, 910, v2] for v1, v2 in rows], np.float32).reshape(-1, 4)
        return boxes_from_arrays(a, np.full(len(a), 0.9, np.float32), np.zeros(len(a), np.uint8))


def test_cut_cones_are_dropped_at_the_moved_rows():
    """EDGE_PX uses the frame's rows: a box ending a row above the moved strip's bottom is a cut cone there,
    and a whole cone in the strip at its calibrated rows."""
    plan = CALIB.strip_plan()
    nominal = CropSpec(370, 466, 0, 1920, 1)
    far = FarBand(nominal, _Recorder(), plan=plan)
    moved, clamped = far.crop_for(0.5, 0.0)  # nose down: the far rows move up
    assert not clamped and moved.v1 <= nominal.v1 - 6 and moved.height_full_px == 96
    far.detector.box_rows = lambda c: [(moved.v1 - 30.0, moved.v1 - 1.0)]
    strip = np.zeros((96, 1920, 3), np.uint8)
    assert len(far.detect(strip, moved)) == 0
    assert len(far.detect(strip, nominal)) == 1
    assert len(far.detect(strip)) == 1  # without a frame's crop: the calibrated rows


def test_pipeline_moves_the_strip_with_the_attitude_and_counts_the_clamped_frames():
    """attitude imu: frame 1 at the calibration's attitude (rows 370-466); the IMU then reads 2 deg nose up at
    frame 2's stamp: frame 2's strip moves down about 34 rows (the previous frame's attitude plus what the IMU
    turned since), with the adapter cutting those rows; 40 deg: clamped to the image's bottom and counted. The
    strip's IMU reads are not counted as the estimator's (a frame without a fresh sample counts once)."""
    from cone_perception.attitude import ImuAttitude
    from cone_perception.pipeline import Pipeline
    from cone_perception.synth.motion import quat_from_rpy

    img = np.repeat(np.arange(1080, dtype=np.uint16)[:, None] % 256, 1920, 1).astype(np.uint8)
    bgr = np.ascontiguousarray(np.dstack([img] * 3))
    imu = ImuAttitude()
    band, strip = _Recorder(), _Recorder()
    far = FarBand(CropSpec(370, 466, 0, 1920, 1), strip, plan=CALIB.strip_plan())
    pipe = Pipeline(CALIB, band, "imu", imu, far)
    rows = []
    for i, pitch in enumerate((0.0, -2.0, -2.0, -40.0)):
        imu.add(i * 100_000_000, quat_from_rpy(0.0, np.radians(pitch), 0.0))
        pipe.process_raw("bgr8", 1920, 1080, 5760, bgr.tobytes(), stamp_ns=i * 100_000_000)
        rows.append(pipe.strip_rows)
        c = strip.crops[-1]
        assert (c.v0, c.v1) == pipe.strip_rows and strip.shapes[-1] == (96, 1920, 3)
        assert strip.pixels[-1] == [c.v0 % 256, (c.v1 - 1) % 256]  # the adapter cut this frame's rows
    assert rows[0] == (370, 466)
    assert rows[1][0] - 370 == pytest.approx(34, abs=3) and rows[1] == rows[2]
    assert rows[3] == (984, 1080)
    assert pipe.strip_counts == {"frames": 4, "clamped": 1}
    assert imu.counts.stale_at_frame == 0
    pipe.process_raw("bgr8", 1920, 1080, 5760, bgr.tobytes(), stamp_ns=10 * 100_000_000)  # no fresh IMU sample
    assert imu.counts.stale_at_frame == 1 and pipe.strip_rows == (984, 1080)
