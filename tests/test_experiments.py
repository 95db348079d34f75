"""Every script in docs/experiments/ runs: its imports resolve against today's package and ``--help`` prints its usage.

The scripts back figures and decisions the docs still state (docs/decisions.md, the model cards, docs/*.md); a
script that no test runs breaks silently when the package moves. All of them run in ONE interpreter (the package and
torch imported once, the check under a minute): ``runpy`` runs each as ``__main__`` with ``--help``, or only imports
it where its ``__main__`` has no ``--help`` and would start the experiment (:data:`IMPORT_ONLY`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "docs" / "experiments"

#: The scripts kept, each checked below; a new script joins this list (test_every_script_is_checked).
SCRIPTS = (
    "attitude_designs", "attitude_fused_designs", "attitude_gated_designs", "attitude_heldout", "band_rows",
    "box_model_scales", "box_pairs", "false_cones", "false_cones_designs", "false_cones_ray", "far_box_model", "far_cadence_cost",
    "far_strip_recall", "finetune_recipe_toy", "kill_restart", "real_false_detections", "small_cone_pr",
    "ort_graph_levels", "strip_per_camera", "suite_attitude_designs", "tracking_designs", "tracking_error_decomposition",
    "weak_confirm",
)
#: Scripts whose ``__main__`` takes no ``--help`` (kill_restart kills and restarts nodes): imported only.
IMPORT_ONLY = ("kill_restart",)

_RUNNER = r"""
import contextlib, io, json, runpy, sys, traceback
out = {}
for path, import_only in json.loads(sys.argv[1]):
    buf, rc = io.StringIO(), 0
    saved_argv, saved_path = sys.argv, list(sys.path)
    sys.argv = [path, "--help"]
    sys.path.insert(0, path.rsplit("/", 1)[0])
    try:
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
            runpy.run_path(path, run_name="smoke_import" if import_only else "__main__")
    except SystemExit as e:
        rc = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:
        rc, _ = 1, buf.write(traceback.format_exc())
    finally:
        sys.argv, sys.path[:] = saved_argv, saved_path
    out[path] = {"rc": rc, "out": buf.getvalue()[:4000]}
print("SMOKE-RESULT " + json.dumps(out))
"""


@pytest.fixture(scope="module")
def results() -> dict:
    """Each script's exit code and output, from one interpreter run from the repository root."""
    jobs = [(str(EXPERIMENTS / f"{name}.py"), name in IMPORT_ONLY) for name in SCRIPTS]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([sys.executable, "-c", _RUNNER, json.dumps(jobs)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("SMOKE-RESULT ")), None)
    assert line is not None, f"the smoke runner died (exit {proc.returncode}): {proc.stderr[-2000:]}"
    return {Path(k).stem: v for k, v in json.loads(line[len("SMOKE-RESULT "):]).items()}


def test_every_script_is_checked():
    on_disk = sorted(p.stem for p in EXPERIMENTS.glob("*.py"))
    assert on_disk == sorted(SCRIPTS), "docs/experiments/ and SCRIPTS differ: add the new script to SCRIPTS"


@pytest.mark.parametrize("name", SCRIPTS)
def test_script_runs(results, name):
    r = results[name]
    assert r["rc"] == 0, f"docs/experiments/{name}.py exits {r['rc']}:\n{r['out']}"
    if name not in IMPORT_ONLY:
        # its usage: argparse's "usage:" line, or the docstring naming the script's own command line
        assert "usage" in r["out"].lower() or f"{name}.py" in r["out"], f"{name}.py --help printed no usage:\n{r['out']}"
