"""One command line: --version, --no-progress wherever a bar is shown, threads default 1, counted nouns."""

from __future__ import annotations

import pytest

from cone_perception import __version__
from cone_perception.cli import main
from cone_perception.words import plural


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"cone-perception {__version__}"


@pytest.mark.parametrize("argv", [
    ["train"], ["detect"], ["eval"], ["export"], ["synth", "dataset"], ["synth", "bag"], ["data", "restore-aspect"],
    ["data", "fsoco-to-yolo"], ["replay"], ["demo"], ["bench"], ["calibrate"], ["soak"], ["validate"],
], ids=lambda a: " ".join(a))
def test_every_command_with_a_bar_takes_no_progress(argv, capsys):
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    assert "--no-progress" in capsys.readouterr().out


def test_synth_quiet_is_an_alias_of_no_progress(capsys):
    with pytest.raises(SystemExit):
        main(["synth", "dataset", "--help"])
    assert "--no-progress, --quiet" in capsys.readouterr().out


def test_threads_default_one_and_plurals(capsys):
    from cone_perception.train.trainer import TrainConfig

    assert TrainConfig(data="", out="").threads == 1
    assert main(["speed", "--sizes", "p", "--backends", "torch", "--imgsz", "64x64", "--frames", "1"]) == 0
    assert "1 thread, 1 frame\n" in capsys.readouterr().out
    assert (plural(1, "thread"), plural(2, "thread"), plural(0, "box", "boxes")) == ("1 thread", "2 threads", "0 boxes")
