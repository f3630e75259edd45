"""Face normals and areas of a triangle mesh in one compiled pass: what the whole scene (scanner_sim.world.scene) and
a site's windows (scanner_sim.world.site) compute alike, so a window's faces have the whole scene's normals to the bit.
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
