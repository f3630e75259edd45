"""The icosphere built in numpy: trimesh's own icosphere to the bit (the shape every rock and moored mine had when
trimesh built it), and a closed sphere with outward faces whatever trimesh does."""

import numpy as np
import pytest
import trimesh

from scanner_sim.world.icosphere import icosphere


@pytest.mark.parametrize("subdivisions", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("radius_m", [1.0, 0.37])
def test_same_vertices_and_faces_as_trimesh(subdivisions, radius_m):
    vertices, faces = icosphere(subdivisions, radius_m)
    reference = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius_m)
    assert vertices.tobytes() == np.asarray(reference.vertices).tobytes()
    assert faces.dtype == np.int64 and np.array_equal(faces, reference.faces)


@pytest.mark.parametrize("subdivisions", [0, 2, 3])
def test_closed_sphere_with_outward_faces(subdivisions):
    """Euler's V - E + F = 2 with every edge shared by two faces, every vertex at the radius, and the signed volume
    positive (outward winding) and approaching 4/3 pi r^3 from below as the sphere is refined."""
    radius_m = 2.0
    vertices, faces = icosphere(subdivisions, radius_m)
    assert len(faces) == 20 * 4**subdivisions and len(vertices) == 10 * 4**subdivisions + 2
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert np.all(uses == 2) and len(vertices) - len(uses) + len(faces) == 2
    np.testing.assert_allclose(np.linalg.norm(vertices, axis=1), radius_m, rtol=1e-12)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    sphere = 4.0 / 3.0 * np.pi * radius_m**3
    assert 0.6 * sphere < volume < sphere
    if subdivisions == 3:
        assert volume > 0.98 * sphere
