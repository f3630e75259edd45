"""An icosphere (a regular icosahedron whose faces are split in four ``subdivisions`` times, every vertex pushed out to
the sphere after each split) in numpy: the rocks' and the moored mines' shape, built without importing trimesh (about
a second of a run's start-up). Vertex and face order are trimesh's ``creation.icosphere`` (the new vertex of each
unique edge appended in order of its larger then smaller vertex index, each face split into its three corners' faces
then the middle one), so a scene built with either is the same to the bit.
"""

from __future__ import annotations

import math

import numpy as np

_GOLDEN = (1.0 + math.sqrt(5.0)) / 2.0
#: The 12 vertices of the regular icosahedron of unit circumradius: the cyclic permutations of (±1, ±φ, 0) / √(1+φ²).
_A, _B = 1.0 / math.sqrt(1.0 + _GOLDEN**2), _GOLDEN / math.sqrt(1.0 + _GOLDEN**2)
ICOSAHEDRON_VERTICES = np.array([
    [-_A, _B, 0.0], [_A, _B, 0.0], [-_A, -_B, 0.0], [_A, -_B, 0.0],
    [0.0, -_A, _B], [0.0, _A, _B], [0.0, -_A, -_B], [0.0, _A, -_B],
    [_B, 0.0, -_A], [_B, 0.0, _A], [-_B, 0.0, -_A], [-_B, 0.0, _A]])
#: Its 20 faces, wound counter-clockwise seen from outside.
ICOSAHEDRON_FACES = np.array([
    [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6],
    [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
    [8, 6, 7], [9, 8, 1]], dtype=np.int64)


def icosphere(subdivisions: int = 2, radius_m: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (10·4^s + 2, 3) float64 [m] on the sphere of ``radius_m`` about the origin and faces (20·4^s, 3)
    int64 with outward normals, ``s`` = ``subdivisions``."""
    vertices, faces = ICOSAHEDRON_VERTICES.copy(), ICOSAHEDRON_FACES
    for _ in range(subdivisions):
        vertices, faces = _split(vertices, faces)
        vertices = _to_sphere(vertices, radius_m)
    if subdivisions <= 0:
        vertices = _to_sphere(vertices, radius_m)
    return vertices, faces


def _split(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face (m, 3) split in four at its edges' midpoints: vertices (n + unique edges, 3), faces (4m, 3)."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    # Unique edges in order of (larger, smaller) vertex index, the order of trimesh's packed row hashes.
    _, first, inverse = np.unique(edges[:, 1] * len(vertices) + edges[:, 0], return_index=True, return_inverse=True)
    middle = vertices[edges[first]].mean(axis=1)
    mid = inverse.reshape(-1, 3) + len(vertices)
    split = np.column_stack([faces[:, 0], mid[:, 0], mid[:, 2], mid[:, 0], faces[:, 1], mid[:, 1],
                             mid[:, 2], mid[:, 1], faces[:, 2], mid[:, 0], mid[:, 1], mid[:, 2]]).reshape(-1, 3)
    return np.vstack([vertices, middle]), split


def _to_sphere(vertices: np.ndarray, radius_m: float) -> np.ndarray:
    """``vertices`` moved along their directions from the origin onto the sphere of ``radius_m``."""
    scalar = np.sqrt(np.dot(vertices**2, [1, 1, 1]))
    return vertices + vertices / scalar.reshape(-1, 1) * (radius_m - scalar).reshape(-1, 1)
