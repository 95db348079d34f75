"""``cone-perception imu-rest``: the IMU's rest attitude from a bag of the car standing still, refused
(naming why) when the car moved or the window holds too few usable samples."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from cone_perception.attitude import imu_rest
from cone_perception.cli import main
from cone_perception.data import bagio
from cone_perception.errors import ConfigError
from cone_perception.synth.motion import Drive, imu_samples
from cone_perception.synth.writers import _imu_msg

FPS = 20.0


def _bag(tmp_path, name: str, pitch_deg: np.ndarray, roll_deg: np.ndarray, seed: int = 4, nan_at: tuple = ()):
    """A bag of the synthetic IMU (its noise and bias model) for a body at these angles, and the bias drawn."""
    n = len(pitch_deg)
    z = np.zeros(n)
    drive = Drive(z, z, z, z, pitch_deg, roll_deg, pitch_deg, roll_deg)
    bias_roll, bias_pitch = np.degrees(np.radians(np.random.default_rng(seed).normal(0.0, 0.05, 2)))
    _, samples = imu_samples(drive, np.full(n, 0.3), FPS, np.random.default_rng(seed))
    for i in nan_at:
        samples[i].quat_xyzw = np.array([np.nan, 0.0, 0.0, 1.0])
    stamps = [10**9 + int(i * 1e9 / FPS) for i in range(n)]
    path = tmp_path / name
    bagio.write_bag(path, {"/imu": bagio.IMU}, [("/imu", t, _imu_msg(s, t)) for s, t in zip(samples, stamps)])
    return path, (bias_pitch, bias_roll)


def test_rest_attitude_of_a_still_car_printed_and_written(tmp_path, capsys):
    n = 80
    bag, (bp, br) = _bag(tmp_path, "still", np.full(n, 0.4), np.full(n, -0.25), nan_at=(3, 7))
    out = tmp_path / "rest.params.yaml"
    assert main(["imu-rest", str(bag), "--seconds", "3", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    p, r = (float(v) for v in text.split("imu_rest_deg: [")[1].split("]")[0].split(","))
    assert p == pytest.approx(0.4 + bp, abs=0.02) and r == pytest.approx(-0.25 + br, abs=0.02)
    assert f"replay: --imu-rest {p},{r}" in text and "nan 2" in text  # the two NaN messages dropped, counted
    assert yaml.safe_load(out.read_text())["/**"]["ros__parameters"]["imu_rest_deg"] == [p, r]
    assert main(["imu-rest", str(bag), "--start", "1", "--seconds", "2", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["n"] == 40 and d["imu_rest_deg"][0]  # the window is [1 s, 3 s): 40 samples at 20 Hz == pytest.approx(p, abs=0.02)


def test_a_moving_car_is_refused_naming_why(tmp_path, capsys):
    t = np.arange(60) / FPS
    bag, _ = _bag(tmp_path, "moving", 0.5 * np.sin(2 * np.pi * 1.5 * t), 0.2 * np.sin(2 * np.pi * 0.9 * t))
    assert main(["imu-rest", str(bag), "--seconds", "3"]) == 2
    err = capsys.readouterr().err
    assert "the car moved" in err and "angular rate" in err and "pitch / roll" in err


def test_too_few_samples_and_a_missing_topic_are_refused(tmp_path, capsys):
    bag, _ = _bag(tmp_path, "short", np.zeros(38), np.zeros(38), nan_at=tuple(range(0, 38, 2)))
    assert main(["imu-rest", str(bag), "--seconds", "5"]) == 2
    err = capsys.readouterr().err
    assert "only 19 usable IMU samples in the window, need >= 20" in err and "nan 19" in err
    assert main(["imu-rest", str(bag), "--imu-topic", "/imu/data"]) == 2
    assert "/imu/data" in capsys.readouterr().err


def test_core_checks_acceleration_alone():
    """A car rolling straight and level at changing speed: still angles, but the acceleration moves."""
    n = 60
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    acc = np.column_stack([np.linspace(-2.0, 2.0, n), np.zeros(n), np.full(n, 9.81)])
    stamps = np.arange(n) * 50_000_000
    with pytest.raises(ConfigError, match="acceleration scatters"):
        imu_rest(stamps, q, np.zeros((n, 3)), acc, "test")
    r = imu_rest(stamps, q, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)), "test")
    assert (r.pitch_deg, r.roll_deg, r.n) == (0.0, 0.0, n)


def test_a_synthetic_bag_with_a_standing_phase_gives_its_imu_bias(tmp_path, capsys):
    """`synth bag --stand 2`: two seconds of /imu alone before the drive, which `imu-rest --seconds 2`
    averages to the IMU's bias (the drive's own IMU readings do not change with the standing phase)."""
    args = ["synth", "bag", "--seconds", "0.3", "--fps", "20", "--size", "320x180", "--seed", "9", "--no-progress"]
    assert main(args + ["--out", str(tmp_path / "plain")]) == 0
    assert main(args + ["--stand", "2", "--out", str(tmp_path / "stand")]) == 0
    capsys.readouterr()
    plain = [(m.log_stamp_ns, m.raw) for m in bagio.read_messages(tmp_path / "plain", "/imu")]
    stand = [(m.log_stamp_ns, m.raw) for m in bagio.read_messages(tmp_path / "stand", "/imu")]
    assert len(stand) == len(plain) + 40 and stand[40:] == plain
    assert max(t for t, _ in stand[:40]) < min(t for t, _ in plain)
    assert main(["imu-rest", str(tmp_path / "stand"), "--seconds", "2", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    bias_roll, bias_pitch = np.random.default_rng([9, 15]).normal(0.0, 0.05, 2)  # synth/motion.py's first draw
    assert d["n"] == 40 and d["imu_rest_deg"] == pytest.approx([bias_pitch, bias_roll], abs=0.02)
    assert main(["imu-rest", str(tmp_path / "stand"), "--seconds", "2.5"]) == 2  # reaches into the drive
    assert "the car moved" in capsys.readouterr().err
    assert main(args + ["--stand", "-1", "--out", str(tmp_path / "bad")]) == 2
    assert "--stand" in capsys.readouterr().err
