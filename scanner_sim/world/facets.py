"""Face normals and areas of a triangle mesh in one compiled pass: what the whole scene (scanner_sim.world.scene) and
a site's windows (scanner_sim.world.site) compute alike, so a window's faces have the whole scene's normals to the bit;
and the area test of a degenerate face (the scene drops them; a mesh file of nothing else is refused).
"""

from __future__ import annotations

import math

import numpy as np

from muls.infra.runtime import kernel


@kernel(nogil=True)
def face_geometry(vertices, faces):
    """Unit normal (n, 3) (right-hand winding; nan for a degenerate face) and twice the area (n,) of each face
    (n, 3) of ``vertices`` (m, 3) float64, in one pass: the same arithmetic as numpy's cross and norm."""
    n = faces.shape[0]
    normal = np.empty((n, 3))
    area2 = np.empty(n)
    for i in range(n):
        a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
        e1x, e1y, e1z = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        e2x, e2y, e2z = vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1], vertices[c, 2] - vertices[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        area2[i] = length
        if length > 0.0:
            normal[i, 0], normal[i, 1], normal[i, 2] = nx / length, ny / length, nz / length
        else:
            normal[i, 0], normal[i, 1], normal[i, 2] = np.nan, np.nan, np.nan
    return normal, area2


#: A triangle with twice its area below this times the square of its mesh's size is degenerate.
DEGENERATE_AREA = 1e-14


def mesh_scale(v: np.ndarray) -> float:
    """The size [m] of a mesh of vertices v (n, 3): its bounding box's longest side (1 for no vertices, at least 1e-12)."""
    return max(1e-12, float(np.ptp(v, axis=0).max()) if len(v) else 1.0)


def nondegenerate(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(m,) bool: the faces f (m, 3) of vertices v (n, 3) that are not degenerate."""
    return face_geometry(np.ascontiguousarray(v, np.float64), np.ascontiguousarray(f, np.int64))[1] > (
        DEGENERATE_AREA * mesh_scale(v) ** 2)
