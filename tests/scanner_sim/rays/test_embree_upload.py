"""A mesh uploaded whole into embreex's scene answers every query as embreex's own ``TriangleMesh`` upload does."""

import sys

import numpy as np
import pytest

pytest.importorskip("embreex")

from embreex import rtcore_scene  # noqa: E402
from embreex.mesh_construction import TriangleMesh  # noqa: E402

from scanner_sim.rays import embree_upload  # noqa: E402
from scanner_sim.rays.embree_upload import embree_scene  # noqa: E402


def _mesh(seed=3):
    """A rough 60 x 40 height field (float32) with 300 loose triangles over it, shared and unshared vertices."""
    rng = np.random.default_rng(seed)
    nx, ny = 60, 40
    x, y = np.meshgrid(np.linspace(-6, 6, nx), np.linspace(-4, 4, ny))
    z = -5.0 + 0.3 * rng.standard_normal((ny, nx))
    grid = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    i = (np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()
    faces = np.concatenate([np.column_stack([i, i + 1, i + nx]), np.column_stack([i + 1, i + nx + 1, i + nx])])
    loose = rng.uniform([-6, -4, -4.8], [6, 4, -2], (900, 3))
    faces = np.concatenate([faces, grid.shape[0] + np.arange(900).reshape(300, 3)])
    return np.vstack([grid, loose]).astype(np.float32), faces.astype(np.int32)


def _rays(n=20000, seed=4):
    rng = np.random.default_rng(seed)
    origins = rng.uniform([-7, -5, -1], [7, 5, 1], (n, 3)).astype(np.float32)
    directions = rng.normal(size=(n, 3)) + [0, 0, -2.0]
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return origins, directions.astype(np.float32), rng.uniform(0, 8, n).astype(np.float32)


def _answers(scene, origins, directions, lengths):
    first = scene.run(origins, directions, output=1)
    return {**first, "occluded": scene.run(origins, directions, dists=lengths, query="OCCLUDED")}


def _triangle_mesh_scene(vertices, faces):
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene=scene, vertices=vertices, indices=faces)
    return scene


def test_whole_buffers_give_triangle_meshs_hits_bit_for_bit():
    """First hits (triangle, distance, barycentrics, normal) and occlusion of 20,000 rays, about half of them hitting:
    the same numbers from both uploads (the same buffers, so the same BVH)."""
    vertices, faces = _mesh()
    rays = _rays()
    expected = _answers(_triangle_mesh_scene(vertices, faces), *rays)
    got = _answers(embree_scene(vertices, faces), *rays)
    assert 0.3 < np.mean(expected["primID"] >= 0) < 0.9
    for key, value in expected.items():
        np.testing.assert_array_equal(got[key], value, err_msg=key)


@pytest.mark.skipif(sys.platform != "linux", reason="the library is found among /proc/self/maps")
def test_the_whole_buffer_path_is_the_one_taken_here(monkeypatch):
    """On Linux with the pinned embreex the layout is confirmed, and no mesh goes through ``TriangleMesh``: were
    a new embreex to move its fields, this fails while the runs still work through the fallback."""
    vertices, faces = _mesh()
    rays = _rays(2000)
    expected = _answers(_triangle_mesh_scene(vertices, faces), *rays)

    def refused(**_):
        raise AssertionError("TriangleMesh was used")

    monkeypatch.setattr("embreex.mesh_construction.TriangleMesh", refused)
    got = _answers(embree_scene(vertices, faces), *rays)
    np.testing.assert_array_equal(got["primID"], expected["primID"])


def test_an_unknown_layout_falls_back_to_triangle_mesh(monkeypatch):
    """A scene object of another size than the layout this module knows is never read: the mesh goes in through
    ``TriangleMesh`` and answers the same."""
    monkeypatch.setattr(embree_upload, "_SCENE_SIZE", embree_upload._SCENE_SIZE + 8)
    vertices, faces = _mesh()
    rays = _rays(2000)
    expected = _answers(_triangle_mesh_scene(vertices, faces), *rays)
    uploads = []

    def recorded(**kwargs):
        uploads.append(kwargs["indices"].shape[0])
        return TriangleMesh(**kwargs)

    monkeypatch.setattr("embreex.mesh_construction.TriangleMesh", recorded)
    got = _answers(embree_scene(vertices, faces), *rays)
    assert uploads == [faces.shape[0]]
    for key, value in expected.items():
        np.testing.assert_array_equal(got[key], value, err_msg=key)
