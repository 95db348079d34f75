"""``cone-perception bench report``: its tables land between their markers and nowhere else; bad topics and
documents are refused before anything runs (the measurements themselves are the commands' own, tested there)."""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest

from cone_perception.bench.report import TOPICS, machine, planned_runs, run_report, stamp, write_section
from cone_perception.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]

DOC = """# Title
intro
<!-- bench report speed -->
old speed table
<!-- /bench report speed -->
between
<!-- bench report real -->
old real table
<!-- /bench report real -->
end
"""


def test_write_section_replaces_only_its_topic(tmp_path):
    doc = tmp_path / "b.md"
    doc.write_text(DOC)
    write_section(doc, "speed", ["| a | b |", "|---|---|", "| 1 | 2 |"])
    text = doc.read_text()
    assert "old speed table" not in text and "| 1 | 2 |" in text
    assert "old real table" in text and text.startswith("# Title\nintro\n") and text.endswith("end\n")
    write_section(doc, "speed", ["new"])  # twice: the markers stay, the body is replaced again
    assert doc.read_text().count("<!-- bench report speed -->") == 1
    assert "| 1 | 2 |" not in doc.read_text() and "<!-- bench report speed -->\nnew\n<!-- /bench report speed -->" in doc.read_text()


def test_write_section_without_markers_names_the_document_and_topic(tmp_path):
    doc = tmp_path / "b.md"
    doc.write_text(DOC)
    with pytest.raises(ConfigError, match="attitude"):
        write_section(doc, "attitude", ["x"])
    assert doc.read_text() == DOC


def test_the_shipped_document_has_every_topics_markers():
    text = (ROOT / "docs" / "benchmarks.md").read_text()
    for topic in TOPICS:
        begin, end = text.find(f"<!-- bench report {topic} -->"), text.find(f"<!-- /bench report {topic} -->")
        assert 0 <= begin < end, topic
    assert len(text.splitlines()) <= 500


def test_unknown_topic_or_missing_document_is_refused_before_any_run(tmp_path):
    doc = tmp_path / "b.md"
    doc.write_text(DOC)
    with pytest.raises(ConfigError, match="unknown topic"):
        run_report(doc, ["speed", "nonsense"], True, tmp_path / "work", tmp_path, progress=False)
    with pytest.raises(ConfigError, match="not found"):
        run_report(tmp_path / "none.md", ["speed"], True, tmp_path / "work", tmp_path, progress=False)
    assert not (tmp_path / "work").exists()


def test_planned_runs_count_the_drives_once():
    # quick: one drive; its synth bag and default replay are shared by rendered, attitude and tracking
    assert planned_runs(["rendered"], True) == 2
    assert planned_runs(["rendered", "attitude", "tracking"], True) == 2 + 3 + 1
    assert planned_runs(["attitude"], False) == 4 + 6
    assert planned_runs(["speed", "real", "robustness"], False) == 8 + 8 + 2  # speed: 7 pipelines + n's forward


def test_stamp_names_the_machine_and_mode():
    line = stamp(time.perf_counter(), 0.0, quick=True)
    assert f"{os.cpu_count()} cores" in machine() and machine() in line
    assert "quick mode" in line and re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", line)
    assert "quick mode" not in stamp(time.perf_counter(), None, quick=False)


def test_the_validation_table_is_the_suites_spread_figure_by_figure():
    """The ``validation`` topic's table reads a ``validate`` run's suite.json: each figure's median, worst tenth and
    worst drive, a failed drive named."""
    from cone_perception.bench.report import suite_section

    dist = {"recall_25_40": {"n": 3, "median": 0.9, "worst_tenth": 0.82, "worst": 0.7, "worst_drive": "720-wide"},
            "false_per_frame": {"n": 3, "median": 0.5, "worst_tenth": 1.7, "worst": 21.4, "worst_drive": "720-wide"}}
    suite = {"distribution": dist, "drives": [{}, {}, {}], "seconds": 4.0, "fps": 10.0, "failed": ["bad"]}
    sec = suite_section(suite, quick=True)
    text = "\n".join(sec.lines)
    assert "| /cones recall: 25-40 m | 0.900 | 0.820 | 0.700 (720-wide) |" in text
    assert "| /cones recall: false/frame | 0.500 | 1.700 | 21.400 (720-wide) |" in text
    assert len(sec.lines) == 2 + 2  # the header and the rule, one row per figure in the suite
    assert sec.commands == ["cone-perception validate --out DIR --quick"] and "failed drives: bad" in sec.notes
