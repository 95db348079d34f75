"""Calibration YAML: loading, saving, and an error naming file and field for every bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cone_perception.errors import ConfigError
from cone_perception.geometry.calib import calibration_from_dict, load_calibration, save_calibration
from cone_perception.resources import calib_dir

EXAMPLE = calib_dir() / "example_mainhoop.yaml"


def _example() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def _write(tmp_path: Path, data) -> Path:
    p = tmp_path / "cam.yaml"
    p.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return p


def test_shipped_example_loads_by_name_and_by_path() -> None:
    a = load_calibration("example_mainhoop")
    b = load_calibration(EXAMPLE)
    assert a.camera == "example_mainhoop" and a.image_width == 1920 and a.image_height == 1080
    np.testing.assert_array_equal(a.H_F_B, b.H_F_B)
    assert (a.crop.out_width, a.crop.out_height) == (960, 288)
    assert a.frame_id == "rear_axle"
    assert a.foot_points == ("bottom_center",) * 5  # bottom centre + foot offset, not the thesis corners
    assert a.foot_offset_m == (0.15, 0.15, 0.15, 0.19, 0.15)


def test_save_and_load_round_trip_keeps_everything(tmp_path: Path) -> None:
    a = load_calibration("example_mainhoop")
    a.dist_coeffs = np.array([-0.1, 0.01, 0.0, 0.0, 0.0])
    p = save_calibration(a, tmp_path / "sub" / "copy.yaml", header="test copy")
    b = load_calibration(p)
    np.testing.assert_allclose(b.H_S_B, a.H_S_B, rtol=1e-15)
    np.testing.assert_allclose(b.T_F_S, a.T_F_S)
    np.testing.assert_allclose(b.dist_coeffs, a.dist_coeffs)
    assert b.crop == a.crop and b.foot_points == a.foot_points and b.extra == a.extra
    assert p.read_text().startswith("# test copy")


def _mut(path: list, value):
    def f(d):
        cur = d
        for k in path[:-1]:
            cur = cur[k]
        if value is KeyError:
            del cur[path[-1]]
        else:
            cur[path[-1]] = value
        return d

    return f


@pytest.mark.parametrize(
    "change,field,words",
    [
        (_mut(["H_S_B"], KeyError), "H_S_B", "missing"),
        (_mut(["H_S_B"], [[1, 0], [0, 1]]), "H_S_B", "shape"),
        (_mut(["H_S_B"], [[1, 0, 0], [0, ".nan", 0], [0, 0, 1]]), "H_S_B", "must be a 3x3"),
        (_mut(["H_S_B"], [[1, 0, 0], [0, float("nan"), 0], [0, 0, 1]]), "H_S_B", "non-finite"),
        (_mut(["H_S_B"], [[1, 2, 3], [2, 4, 6], [0, 0, 1]]), "H_S_B", "singular"),
        (_mut(["T_F_S"], [[1, 0, 1], [0, 1, 0], [0.1, 0, 1]]), "T_F_S", "last row"),
        (_mut(["T_F_S"], [[2, 0, 1], [0, 1, 0], [0, 0, 1]]), "T_F_S", "rotation"),
        (_mut(["T_F_S"], [[1, 0, float("inf")], [0, 1, 0], [0, 0, 1]]), "T_F_S", "non-finite"),
        (_mut(["crop", "v1"], 1200), "crop.v0/v1", "inside"),
        (_mut(["crop", "u0"], -2), "crop.u0/u1", "inside"),
        (_mut(["crop", "v0"], "top"), "crop.v0", "integer"),
        (_mut(["crop"], [384, 960]), "crop", "mapping"),
        (_mut(["downscale"], 3), "downscale", "one of"),
        (_mut(["foot_points", "blue"], "top_left"), "foot_points.blue", "unknown rule"),
        (_mut(["foot_points", "purple"], "bottom_left"), "foot_points.purple", "unknown class"),
        (_mut(["image_width"], -1920), "image_width", "> 0"),
        (_mut(["image_width"], 1_000_000_000), "image_width", "at most"),  # issue 20: was an OOM traceback
        (_mut(["image_height"], 20_000), "image_height", "at most"),
        (_mut(["max_range_m"], 0), "max_range_m", "> 0"),
        (_mut(["pixel_sigma", "u"], "big"), "pixel_sigma.u", "number"),
        (_mut(["dist_coeffs"], [0.1, 0.2, 0.3]), "dist_coeffs", "4, 5, 8"),
    ],
)
def test_bad_field_names_file_and_field(tmp_path: Path, change, field, words) -> None:
    p = _write(tmp_path, change(_example()))
    with pytest.raises(ConfigError) as e:
        load_calibration(p)
    assert e.value.field == field
    assert str(p) in str(e.value) and field in str(e.value) and words in str(e.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found") as e:
        load_calibration(tmp_path / "nope.yaml")
    assert "nope.yaml" in str(e.value)


def test_not_yaml_and_not_a_mapping(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_calibration(_write(tmp_path, "camera: [unclosed\n  H: {"))
    with pytest.raises(ConfigError, match="mapping"):
        load_calibration(_write(tmp_path, "- 1\n- 2\n"))


def test_unreadable_file(tmp_path: Path, monkeypatch) -> None:
    # chmod 0 does not stop root (CI), so the OS refusal is simulated at the read call
    p = _write(tmp_path, _example())

    def refuse(self, *a, **k):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_text", refuse)
    with pytest.raises(ConfigError, match="cannot read: Permission denied"):
        load_calibration(p)


def test_binary_file(tmp_path: Path) -> None:
    p = tmp_path / "cam.yaml"
    p.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(ConfigError, match="not UTF-8"):
        load_calibration(p)


def test_unreadable_path_is_a_directory(tmp_path: Path) -> None:
    d = tmp_path / "dir.yaml"
    d.mkdir()
    with pytest.raises(ConfigError) as e:
        load_calibration(d)
    assert "dir.yaml" in str(e.value)


def test_h_with_w_zero_at_the_reference_pixel_is_rejected() -> None:
    d = _example()
    # third row makes w = 0 at the bottom-centre pixel (960, 1079)
    d["H_S_B"] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, -1079.0]]
    d["T_F_S"] = np.eye(3).tolist()
    with pytest.raises(ConfigError, match="w = 0"):
        calibration_from_dict(d, "mem.yaml")
