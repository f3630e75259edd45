"""A panel labelled seabed is the seabed: its top surface gives the height field that coverage, altitude following
and objects placed by [x, y] read, as a mesh labelled seabed does.

Root cause of the regression these tests pin: ``SceneConfig.has_seabed`` counted any object labelled seabed, so
the pass set out to measure coverage, but the scene build sampled a height field from meshes only; a scene whose
seabed is a panel (the common flat target) then stopped with "coverage: the scene has no seabed section". The
tests of the geometry alone (``PassSetup.simulate_chunk``) never reached the coverage tally, so they stayed green.
"""

import json
import subprocess
import sys

import numpy as np
import pytest
import yaml
from conftest import ROOT

import scanner_sim
from scanner_sim.config import load_scene, parse_scene
from scanner_sim.world.scene import build_scene

FAILURES = ROOT / "scenes" / "failures"


def _labelled_seabed(name: str, panels: set[str] | None = None) -> dict:
    """The shipped failure scene ``name`` with its panels named in ``panels`` (all when None) labelled seabed."""
    data = yaml.safe_load((FAILURES / f"{name}.yaml").read_text())
    for obj in data["objects"]:
        if panels is None or obj["name"] in panels:
            obj["label"] = "seabed"
    return data


def _pass(data: dict, pulses: int):
    return scanner_sim.simulate_pass(parse_scene(data), scanner_sim.PassOptions(max_pulses=pulses, progress=False))


def test_static_plate_labelled_seabed_at_1_75_m_runs_with_coverage():
    """A sand plate 1.75 m below a static lidar, labelled seabed (blind_zone_edge's geometry): the pass runs, its
    plate is the height field (z = -2.75 m over the plate, gaps beyond it) and the coverage reached it."""
    data = _labelled_seabed("blind_zone_edge")
    scene = build_scene(parse_scene(data))
    plate_z = data["objects"][0]["center_m"][2]
    assert scene.heightfield.height(np.array([0.0, 1.4, -1.4]), np.array([0.0, -1.4, 1.4])) == pytest.approx(plate_z)
    assert scene.heightfield.extent_m == pytest.approx((-1.5, 1.5, -1.5, 1.5))
    assert scene.objects[0].kind == "seabed"
    result = _pass(data, 300)
    coverage = result.summary["coverage"]
    assert coverage["reached_area_m2"] > 0 and coverage["objects"] == []
    assert result.summary["seabed"]["source"] == ["panel 'plate'"]
    assert np.median(np.abs(result.points.xyz[:, 2] - plate_z)) < 0.05


def test_edge_scene_with_scanning_sector_labelled_seabed_runs():
    """step_edges (five panels stepping down 0.2 to 2 m, a 30 degree oscillating sector) with every panel labelled
    seabed: the height field over each panel's centre is that panel's depth (read from the scene file, not the
    sampling), the pass runs and its points lie on the panels."""
    data = _labelled_seabed("step_edges")
    scene = build_scene(parse_scene(data))
    centres = np.array([o["center_m"] for o in data["objects"]])
    np.testing.assert_allclose(scene.heightfield.height(centres[:, 0] + 0.05, centres[:, 1]), centres[:, 2])
    result = _pass(data, 600)
    assert result.summary["coverage"]["reached_area_m2"] > 0
    xyz = result.points.xyz
    assert len(xyz) > 500
    on_a_panel = np.abs(xyz[:, 2] - scene.heightfield.height(xyz[:, 0], xyz[:, 1])) < 0.15
    assert on_a_panel.mean() > 0.9


def test_far_panel_labelled_seabed_is_ranged_behind_the_near_clipped_echo_in_a_whole_run(tmp_path):
    """The shipped scene behind_clipped_echo (a bright plate half across the beam whose echo clips, sand labelled
    seabed 2 m behind it), as a whole pass: `scanner-sim run` exits 0 and writes its coverage, and every pulse
    ranges both the plate and the sand behind it (as the geometry-only test of the failure modes shows)."""
    run = subprocess.run([sys.executable, "-m", "scanner_sim.cli", "run", str(FAILURES / "behind_clipped_echo.yaml"),
                          "--max-pulses", "200", "--out", str(tmp_path / "run"), "--no-render", "--quiet"],
                         capture_output=True, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin"})
    assert run.returncode == 0, run.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["coverage"]["reached_area_m2"] > 0
    cfg = load_scene(FAILURES / "behind_clipped_echo.yaml")
    points = scanner_sim.simulate_pass(cfg, scanner_sim.PassOptions(max_pulses=200, progress=False)).points
    plate_z, sand_z = (o.center_m[2] for o in cfg.objects)
    near, far = np.abs(points.xyz[:, 2] - plate_z) < 0.15, np.abs(points.xyz[:, 2] - sand_z) < 0.15
    assert np.count_nonzero(near & points.saturated) == 200
    assert np.count_nonzero(far) >= 198 and np.all(near | far)


def test_other_objects_labelled_seabed_are_only_classed_so():
    """A cable labelled seabed, or a wall (a panel standing on edge, with no top surface), is a class of points,
    not the seabed: a scene with nothing else has no seabed (it ran before panels and meshes labelled seabed
    became the seabed, and runs still)."""
    data = _labelled_seabed("blind_zone_edge", panels=set())
    data["objects"].append({"type": "cable", "name": "rope", "points_m": [[-1, 0, -2.5], [1, 0, -2.5]],
                            "diameter_m": 0.05, "label": "seabed"})
    data["objects"].append({"type": "panel", "name": "wall", "center_m": [2, 0, -2], "size_m": [2, 2],
                            "normal": [-1, 0, 0], "label": "seabed"})
    cfg = parse_scene(data)
    assert not cfg.has_seabed and build_scene(cfg).heightfield is None
    assert "coverage" not in _pass(data, 50).summary
