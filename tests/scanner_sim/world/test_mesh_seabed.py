"""Any seabed is a seabed: a mesh file labelled seabed is followed at altitude and measured for coverage like the
procedural seabed, and the Python API takes a trimesh.Trimesh in memory."""

import numpy as np
import pytest

import scanner_sim
from scanner_sim.config import parse_scene
from scanner_sim.world.scene import build_scene


def slope_mesh(path, size=(40.0, 20.0), step=0.5, depth=15.0, slope=0.05):
    """A seabed mesh file (PLY): z = -depth + slope x + 0.3 sin(y / 2) over size [m], a grid of ``step``."""
    import trimesh

    nx, ny = int(size[0] / step) + 1, int(size[1] / step) + 1
    gx, gy = np.meshgrid(np.linspace(0, size[0], nx), np.linspace(0, size[1], ny))
    z = -depth + slope * gx + 0.3 * np.sin(gy / 2.0)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.r_[np.c_[a, b, d], np.c_[a, d, c]]
    trimesh.Trimesh(np.c_[gx.ravel(), gy.ravel(), z.ravel()], faces, process=False).export(path)
    return lambda x, y: -depth + slope * x + 0.3 * np.sin(y / 2.0)


def mesh_scene(tmp_path, file="seabed.ply"):
    return parse_scene({
        "format_version": 1, "name": "mesh_seabed", "water": "clean_ocean",
        "objects": [{"type": "mesh", "name": "survey_mesh", "file": file, "label": "seabed",
                     "material": "terrigenous_sand"}],
        "platform": {"mode": "waypoints", "altitude_m": 4.0, "follow_length_m": 1.5,
                     "waypoints_m": [[5.0, 10.0], [35.0, 10.0]]}}, base_dir=tmp_path)


def test_mesh_seabed_is_followed_at_altitude_and_gets_coverage(tmp_path):
    """A bathymetry converted to a mesh file and labelled seabed: altitude_m was refused ("need a seabed section")
    and no coverage was written, since altitude following and coverage read only the procedural seabed's height
    field. Now the mesh's top surface is sampled into a height field: the vehicle holds 4 m above the mesh (the
    surface's own formula, not the sampling, is the check) and the pass measures coverage over it."""
    surface = slope_mesh(tmp_path / "seabed.ply")
    cfg = mesh_scene(tmp_path)
    result = scanner_sim.simulate_pass(cfg, scanner_sim.PassOptions(max_pulses=4000, progress=False))
    table = result.trajectory
    x, y, z = table["position_m"].T
    assert np.abs(z - surface(x, y) - 4.0).max() < 0.1
    coverage = result.summary["coverage"]
    assert coverage["covered_fraction"] > 0.5 and coverage["no_seabed_data_m2"] == 0.0
    assert coverage["objects"] == [] or all(o["name"] != "survey_mesh" for o in coverage["objects"])
    xyz = result.points.xyz
    assert np.median(np.abs(xyz[:, 2] - surface(xyz[:, 0], xyz[:, 1]))) < 0.02


def test_trimesh_in_memory_is_a_seabed(tmp_path):
    """The Python API: a trimesh.Trimesh in place of a mesh file (here the mesh the file would hold)."""
    import trimesh

    surface = slope_mesh(tmp_path / "seabed.ply")
    mesh = trimesh.load(tmp_path / "seabed.ply", force="mesh")
    cfg = mesh_scene(tmp_path, file=mesh)
    built = build_scene(cfg)
    assert built.heightfield.height(20.0, 5.0) == pytest.approx(surface(20.0, 5.0), abs=0.01)
    assert built.objects[0].kind == "seabed"
    result = scanner_sim.simulate_pass(cfg, scanner_sim.PassOptions(max_pulses=500, progress=False))
    assert result.summary["seabed"]["source"] == ["in memory"] and len(result.points.xyz) > 400
