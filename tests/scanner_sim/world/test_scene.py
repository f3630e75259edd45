"""Scene building: seabed height query vs the mesh, cable burial, mines, mesh files, determinism."""

import numpy as np
import pytest
import yaml

from scanner_sim.config import SCENES_DIR, load_scene, parse_scene
from scanner_sim.config.materials import LABELS, MATERIALS
from scanner_sim.rays.caster import RayCaster
from scanner_sim.world.objects import cable_centreline, tube
from scanner_sim.world.scene import build_scene
from scanner_sim.world.terrain import generate_heightfield


@pytest.fixture(scope="module")
def mine_scene():
    return build_scene(load_scene("mine_field"))


def test_height_query_matches_the_mesh_the_rays_see():
    rng = np.random.default_rng(1)
    hf = generate_heightfield((100.0, 50.0), (10, 6), 0.2, 10.0, 0.2, 3.0, 0.7, 0.05, 0.6, 10.0, 0.1, rng)
    from scanner_sim.world.scene import Part, Scene

    v, f = hf.mesh()
    scene = Scene([Part("seabed", "seabed", v, f, LABELS["seabed"], 0.14)], hf)
    xy = np.c_[rng.uniform(96, 104, 500), rng.uniform(48, 52, 500)]
    origins = np.c_[xy, np.zeros(500)] - scene.local_origin
    ray, tri, dist = RayCaster.for_scene(scene).first_hits(origins.astype(np.float32), np.tile(np.float32([0, 0, -1]), (500, 1)))
    assert len(ray) == 500
    np.testing.assert_allclose(-dist.astype(float), hf.height(xy[:, 0], xy[:, 1]), atol=2e-5)  # rays start at z = 0
    assert np.all(scene.face_normal[tri, 2] > 0)  # seabed normals point up


def test_cable_lies_on_the_seabed_buried_by_the_fraction():
    rng = np.random.default_rng(2)
    hf = generate_heightfield((0, 0), (20, 6), 0.05, 10.0, 0.1, 5.0, 0.7, 0.0, 0.6, 0.0, 0.0, rng)
    for burial in (0.0, 0.3, 0.8):
        line = cable_centreline([[-8, 0], [0, 1], [8, 0]], 0.1, burial, hf, stiffness_length_m=0.0)
        ground = hf.height(line[:, 0], line[:, 1])
        np.testing.assert_allclose(line[:, 2] - ground, 0.05 - burial * 0.1, atol=1e-9)
    v, f = tube(line, 0.05, 12)
    assert len(f) == 2 * 12 * (len(line) - 1) + 2 * 12


def test_shipped_scene_objects_and_labels(mine_scene):
    names = [o.name for o in mine_scene.objects]
    assert names[:2] == ["seabed", "rocks"]
    assert {"moored_sphere", "bottom_cylinder", "truncated_cone", "mooring_block"} <= set(names)
    mines = [o for o in mine_scene.objects if o.label == LABELS["mine"]]
    assert len(mines) == 3
    assert mine_scene.object_named("mooring_block").label == LABELS["debris"]
    assert mine_scene.object_named("seabed").reflectance == MATERIALS["mud"].reflectance
    for o in mine_scene.objects:  # per-triangle arrays agree with the object table
        sl = slice(o.face_start, o.face_stop)
        assert np.all(mine_scene.face_object[sl] == o.object_id) and np.all(mine_scene.face_label[sl] == o.label)
    assert mine_scene.n_faces < 400_000


def test_moored_mine_floats_at_its_height(mine_scene):
    o = mine_scene.object_named("moored_sphere")
    verts = mine_scene.vertices[np.unique(mine_scene.faces[o.face_start:o.face_stop])]
    ground = mine_scene.surface_height(-5.0, 0.8)
    assert verts[:, 2].max() == pytest.approx(ground + 1.2 + 0.4, abs=1e-6)  # top of the sphere
    assert verts[:, 2].min() < ground  # the tether reaches into the seabed


def test_mesh_file_sits_on_the_seabed(mine_scene):
    o = mine_scene.object_named("mooring_block")
    verts = mine_scene.vertices[np.unique(mine_scene.faces[o.face_start:o.face_stop])]
    assert verts[:, 2].min() == pytest.approx(float(mine_scene.surface_height(-1.0, 2.0)), abs=1e-9)


def test_build_is_deterministic():
    data = yaml.safe_load((SCENES_DIR / "mine_field.yaml").read_text())
    data["seabed"].update(size_m=[6, 4], resolution_m=0.1)
    data["objects"] = data["objects"][:3]
    data["platform"]["waypoints_m"] = [[-2, 0], [2, 0]]
    a = build_scene(parse_scene(data, SCENES_DIR))
    b = build_scene(parse_scene(data, SCENES_DIR))
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    data["seabed"]["seed"] = 99
    c = build_scene(parse_scene(data, SCENES_DIR))
    assert not np.array_equal(a.vertices, c.vertices)


def test_materials_and_labels_tables():
    assert MATERIALS["carbonate_sand"].reflectance == 0.43
    assert MATERIALS["terrigenous_sand"].reflectance == 0.14
    assert MATERIALS["green_algae"].reflectance == 0.25
    assert MATERIALS["brown_algae"].reflectance == 0.045
    assert MATERIALS["black_painted_aluminium"].reflectance == 0.10
    for name in ("mud", "rock", "polyethylene", "painted_steel"):
        assert MATERIALS[name].source.startswith("assumption")
    assert LABELS["seabed"] == 40 and all(64 <= LABELS[k] <= 255 for k in ("cable", "mine", "panel", "wreck", "rock"))
    assert len(set(LABELS.values())) == len(LABELS)
