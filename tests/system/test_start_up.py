"""The commands that only answer a question (``--help``, ``--version``, ``scenes``, ``schema``, ``validate``) import
none of the heavy libraries a pass needs: the kernel compiler, the ray tracer, the 3-D viewer, the task scheduler
and the raster reader load only when a command's work starts."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from conftest import ROOT

#: Libraries that cost seconds to import and that no question-only command needs.
HEAVY = ("numba", "embreex", "pyvista", "dask", "rasterio")

#: Runs one console script's entry point as the console script does and writes, at exit, the names of the
#: top-level modules it imported to the file named by the first argument.
WRAPPER = """
import json, sys
out, script, *argv = sys.argv[1:]
try:
    if script == "scanner-sim":
        from scanner_sim.cli import main
    else:
        from muls.cli import main
    code = main(argv)
finally:
    with open(out, "w") as f:
        json.dump(sorted({name.split(".")[0] for name in sys.modules}), f)
sys.exit(code)
"""


#: What checking a scene file needs none of: the LAS writer (imported once only to name its error), map projections
#: (a scene without a CRS), SciPy (once imported by the water model for one root finder).
NOT_FOR_CHECKING = ("laspy", "pyproj", "scipy")


def imported_by(argv, tmp_path) -> set[str]:
    """The top-level modules one console-script run of ``argv`` imported (it must succeed and answer on stdout)."""
    modules = tmp_path / "modules.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", WRAPPER, str(modules), *argv], capture_output=True, text=True,
                          cwd=tmp_path, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout  # each answers on stdout (help, version, the scenes, the schema, "OK cable_survey")
    imported = set(json.loads(modules.read_text()))
    assert "scanner_sim" in imported or "muls" in imported  # the list is of this run's imports
    return imported


@pytest.mark.parametrize("argv", [("scanner-sim", "schema"), ("scanner-sim", "validate", "cable_survey")], ids=" ".join)
def test_checking_a_scene_imports_no_writer_projection_or_scipy(argv, tmp_path):
    assert sorted(imported_by(argv, tmp_path) & set(NOT_FOR_CHECKING)) == []


@pytest.mark.parametrize("argv", [
    ("scanner-sim", "--help"), ("scanner-sim", "--version"), ("scanner-sim", "scenes"), ("scanner-sim", "schema"),
    ("scanner-sim", "validate", "cable_survey"), ("muls", "--help"), ("muls", "--version"),
    # the studies' own help, whose defaults once came from the studies' modules (1.0 to 1.5 s, numba imported)
    ("scanner-sim", "coverage", "--help"), ("scanner-sim", "features", "--help"), ("scanner-sim", "plan", "--help"),
    ("scanner-sim", "tradeoff", "--help"),
], ids=" ".join)
def test_question_commands_import_nothing_heavy(argv, tmp_path):
    assert sorted(imported_by(argv, tmp_path) & set(HEAVY)) == []
