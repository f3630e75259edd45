"""The seabed's height field on a grid of coarse cells with bounds (slope, highest seabed node, highest other
object), from which :mod:`scanner_sim.rays.seabed_kernels` proves that nothing can stand in a ray's way: the ``auto``
level's analytic seabed hits (:mod:`scanner_sim.rays.auto`) and every level's shadow rays that need no cast
(:func:`scanner_sim.rays.cast.cast_beams`). Built once per pass, with its :class:`~scanner_sim.rays.cast.CastScene`.
"""

from __future__ import annotations

import numpy as np

from scanner_sim.rays.seabed_kernels import SeabedGrid, rasterise_tops, seabed_planes

#: [m] Side of the coarse cells over which :func:`seabed_grid` bounds the seabed's slope and the other objects.
COARSE_CELL_M = 0.1
#: [m] Side of the blocks of coarse cells over which :func:`seabed_grid` keeps the highest point of anything.
SUPER_CELL_M = 1.0


def seabed_grid(scene, caster, z_top_m: float | None = None):
    """The :class:`scanner_sim.rays.seabed_kernels.SeabedGrid` of ``scene``'s seabed in ``caster``'s local frame, or None
    where the scene has no height field or its seabed faces are not the height field's own, in its order. A height
    field with gaps (``valid``: a raster's no-data cells) has its grid: a gap holds no seabed, so it bounds
    nothing, and a sub-ray over it is left to Embree. ``z_top_m``: the highest local float32 z of the whole scene
    when ``scene`` is a window of it (default: the caster's own)."""
    if no_grid_reason(scene) is not None:
        return None
    hf = scene.heightfield
    sb = next(o for o in scene.objects if o.kind == "seabed")
    ny, nx = hf.shape
    cells = (nx - 1) * (ny - 1)
    faces = scene.faces[sb.face_start:sb.face_stop]
    valid = np.ones((ny - 1, nx - 1), bool) if hf.valid is None else hf.valid
    triangle = np.tile(valid.ravel(), 2)  # the height field's triangles that are seabed faces, in their order
    cell_face = np.full(2 * cells if hf.valid is not None else 0, -1, np.int32)
    if hf.valid is not None:
        cell_face[triangle] = np.arange(faces.shape[0])
    k = max(1, round(COARSE_CELL_M / hf.spacing_m))
    cy, cx = -(-(ny - 1) // k), -(-(nx - 1) // k)

    normal = scene.face_normal[sb.face_start:sb.face_stop]
    gradient = np.empty((cy, cx, 4))
    for axis in (0, 1):  # dz/dx, dz/dy of each seabed triangle: -n_x / n_z, -n_y / n_z (a gap bounds nothing)
        g_lo, g_hi = np.full(2 * cells, np.inf), np.full(2 * cells, -np.inf)
        g_lo[triangle] = g_hi[triangle] = -normal[:, axis] / normal[:, 2]
        gradient[:, :, 2 * axis] = -_block_max(-g_lo.reshape(2, ny - 1, nx - 1).min(axis=0), k)
        gradient[:, :, 2 * axis + 1] = _block_max(g_hi.reshape(2, ny - 1, nx - 1).max(axis=0), k)
    _, mesh_faces = hf.mesh()
    first_vertex = int(faces.min() - mesh_faces.min())  # the height field's node (0, 0) among the caster's vertices
    z = caster.vertices[first_vertex:first_vertex + nx * ny, 2].astype(np.float64).reshape(ny, nx)
    node_top = np.maximum(np.maximum(z[:-1, :-1], z[:-1, 1:]), np.maximum(z[1:, :-1], z[1:, 1:]))
    node_top[~valid] = -np.inf
    x0, y0 = hf.x0_m - scene.local_origin[0], hf.y0_m - scene.local_origin[1]
    object_top = np.full((cy, cx), -np.inf)
    size = k * hf.spacing_m
    rasterise_tops(caster.vertices, caster.faces, 0, sb.face_start, x0, y0, size, object_top)
    rasterise_tops(caster.vertices, caster.faces, sb.face_stop, caster.faces.shape[0], x0, y0, size, object_top)
    seabed_top = _block_max(node_top, k)
    sk = max(1, round(SUPER_CELL_M / (k * hf.spacing_m)))
    super_top = _block_max(np.maximum(seabed_top, object_top), sk)
    plane = np.empty((faces.shape[0], 4))
    seabed_planes(caster.vertices, caster.faces, sb.face_start, sb.face_stop, plane)
    z_top = float(caster.vertices[:, 2].max()) if z_top_m is None else z_top_m
    others = np.concatenate([caster.faces[:sb.face_start], caster.faces[sb.face_stop:]])
    xy = caster.vertices[np.unique(others), :2]  # the seabed's own lie on the height field's nodes
    holds_all = bool(np.all((xy[:, 0] >= x0) & (xy[:, 0] <= x0 + (nx - 1) * hf.spacing_m)
                            & (xy[:, 1] >= y0) & (xy[:, 1] <= y0 + (ny - 1) * hf.spacing_m)))
    return SeabedGrid(float(x0), float(y0), float(hf.spacing_m), int(nx), int(ny), int(sb.face_start), cell_face,
                      int(k),
                      gradient, seabed_top, object_top, z_top + 1e-3, plane,
                      int(sk), super_top, int(scene.face_object[sb.face_start]),
                      float(caster.vertices[caster.faces, 2].min()), holds_all)


def no_grid_reason(scene) -> str | None:
    """Why :func:`seabed_grid` builds no proof grid for ``scene`` (one line, for the trade-off's report of where
    ``auto`` falls back to casting every ray), or None where it builds one."""
    hf = scene.heightfield
    if hf is None:
        return "no height-field seabed (a mesh seabed or none)"
    seabeds = [o for o in scene.objects if o.kind == "seabed"]
    if len(seabeds) != 1:
        return f"{len(seabeds)} seabed objects, the proofs model one"
    sb = seabeds[0]
    faces = scene.faces[sb.face_start:sb.face_stop]
    _, expected = hf.mesh()
    if faces.shape != expected.shape or not np.array_equal(faces - faces.min(), expected - expected.min()):
        return "the seabed's faces are not the height field's own, in its order"
    return None


def _block_max(a: np.ndarray, k: int) -> np.ndarray:
    """The maximum of each k x k block of the 2-D ``a`` (the last blocks padded with -inf)."""
    by, bx = -(-a.shape[0] // k), -(-a.shape[1] // k)
    padded = np.full((by * k, bx * k), -np.inf)
    padded[:a.shape[0], :a.shape[1]] = a
    return padded.reshape(by, k, bx, k).max(axis=(1, 3))

