"""Outputs never overwritten silently: export, calibrate, synth preview and replay refuse an existing
output unless --force (calibrate: tests/test_calibrate_cli.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from cone_perception.cli import main
from cone_perception.data.outfiles import refuse_existing
from cone_perception.detector import default_model_path
from cone_perception.errors import ConfigError


def test_refuse_existing_names_the_file(tmp_path: Path) -> None:
    a, b = tmp_path / "a.onnx", tmp_path / "a.yaml"
    refuse_existing([a, b], False, "export")
    b.write_text("x")
    with pytest.raises(ConfigError, match="a.yaml.*--force"):
        refuse_existing([a, b], False, "export")
    refuse_existing([a, b], True, "export")


@pytest.mark.parametrize("existing", ["m.onnx", "m.onnx.yaml"])
def test_export_refuses_an_existing_output_or_sidecar(tmp_path: Path, capsys, existing: str) -> None:
    (tmp_path / existing).write_text("keep me")
    rc = main(["export", "--model", str(default_model_path()), "--format", "onnx", "--out", str(tmp_path / "m.onnx")])
    assert rc == 2 and existing in capsys.readouterr().err
    assert (tmp_path / existing).read_text() == "keep me"
    assert len(list(tmp_path.iterdir())) == 1


def test_synth_preview_refuses_then_overwrites_with_force(tmp_path: Path, capsys) -> None:
    out = tmp_path / "p.png"
    out.write_bytes(b"keep me")
    assert main(["synth", "preview", "--out", str(out), "--n", "1"]) == 2
    assert out.read_bytes() == b"keep me"
    assert main(["synth", "preview", "--out", str(out), "--n", "1", "--force"]) == 0
    assert out.read_bytes()[:4] == b"\x89PNG" and f"synth preview: wrote {out}" in capsys.readouterr().out


def test_replay_refuses_existing_outputs_and_force_replaces_only_a_bag(tmp_path: Path, capsys) -> None:
    from cone_perception.data.outfiles import remove_bag

    js = tmp_path / "s.json"
    js.write_text("keep me")
    assert main(["replay", str(tmp_path / "nobag"), "--json", str(js)]) == 2
    assert js.read_text() == "keep me" and "--force" in capsys.readouterr().err
    folder = tmp_path / "notabag"
    folder.mkdir()
    (folder / "precious.txt").write_text("x")
    with pytest.raises(ConfigError, match="only a rosbag2"):
        remove_bag(folder)
    assert (folder / "precious.txt").exists()
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}")
    remove_bag(bag)
    assert not bag.exists()
