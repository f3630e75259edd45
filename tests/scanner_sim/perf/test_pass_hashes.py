"""The byte-identity check sees a changed point and nothing else: two passes with one seed hash the same, product by
product, and a pass with one point moved by a single LAS unit (0.1 mm) does not."""

import shutil

import laspy
import numpy as np
from conftest import run_cli

from scanner_sim.perf.pass_hashes import pass_hashes


def _pass(out, seed):
    code, _ = run_cli(["run", "pool_panel", "--max-pulses", "300", "--seed", str(seed), "--waveforms", "4",
                       "--no-render", "--quiet", "--out", str(out)])
    assert code == 0
    return out


def test_same_seed_same_hashes_and_a_moved_point_differs(tmp_path):
    first, again = _pass(tmp_path / "a", 3), _pass(tmp_path / "b", 3)
    hashes = pass_hashes(first)
    assert set(hashes) == {"points", "dropouts", "waveforms"}
    assert pass_hashes(again) == hashes  # the LAS headers differ (creation date), the records do not

    moved = tmp_path / "moved"
    shutil.copytree(first, moved)
    las = laspy.read(moved / "points.las")
    las.points["X"] = las.points["X"] + (np.arange(len(las.points)) == 0)  # the first point, one unit of X
    las.write(moved / "points.las")
    changed = pass_hashes(moved)
    assert changed["points"] != hashes["points"]
    assert {k: v for k, v in changed.items() if k != "points"} == {k: v for k, v in hashes.items() if k != "points"}


def test_other_seed_other_points(tmp_path):
    assert pass_hashes(_pass(tmp_path / "a", 3))["points"] != pass_hashes(_pass(tmp_path / "b", 4))["points"]
