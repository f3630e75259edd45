"""The height field of a seabed given as meshes or panels (objects labelled ``seabed``): what altitude following, the track
checks and coverage read, as they read the procedural seabed's.

The mesh's top surface is sampled on a square grid: each node takes the highest point of the mesh's triangles
above it (a vertical line through the node, met in plan by barycentric coordinates); nodes no triangle covers are
gaps, filled from the nearest covered node for the track to follow. The rays still see the mesh itself.
"""

from __future__ import annotations

import math

import numpy as np

from muls.infra.errors import ParameterError
from muls.infra.runtime import kernel
from scanner_sim.config import ConfigError
from scanner_sim.world.terrain import HeightField

#: Most nodes of a mesh seabed's height field: its spacing grows past the mesh's own edge length to stay below.
MAX_MESH_SEABED_NODES = 4_000_000
#: [m] Largest node spacing of a seabed with a panel among its surfaces: the procedural seabed's default
#: ``resolution_m``, so that a panel's edges and the steps between panels lie within 0.1 m of where they are.
PANEL_SEABED_SPACING_M = 0.1


def mesh_heightfield(vertices: np.ndarray, faces: np.ndarray, spacing_m: float | None = None) -> HeightField:
    """The :class:`HeightField` of the top surface of the mesh ``vertices`` (n, 3) [m], ``faces`` (m, 3), with
    ``valid`` marking the cells whose four nodes the mesh covers. ``spacing_m`` default: the median plan length
    of the mesh's edges, coarsened to at most :data:`MAX_MESH_SEABED_NODES` nodes."""
    v = np.ascontiguousarray(vertices, np.float64)
    f = np.ascontiguousarray(faces, np.int64)
    lo, hi = v[:, :2].min(axis=0), v[:, :2].max(axis=0)
    if spacing_m is None:
        spacing_m = median_edge_m(v, f)
    area = float(np.prod(np.maximum(hi - lo, spacing_m)))
    spacing_m = max(spacing_m, math.sqrt(area / MAX_MESH_SEABED_NODES))
    nx, ny = (int(math.floor((hi - lo)[k] / spacing_m + 1e-9)) + 1 for k in (0, 1))
    if nx < 2 or ny < 2:
        raise ParameterError(f"a seabed mesh {hi[0] - lo[0]:.3g} x {hi[1] - lo[1]:.3g} m in plan: too narrow for a height "
                         f"field at {spacing_m:.3g} m")
    z = np.full((ny, nx), -np.inf)
    _top_surface(v, f, float(lo[0]), float(lo[1]), spacing_m, z)
    covered = np.isfinite(z)
    if not covered.all():
        from scipy import ndimage

        nearest = ndimage.distance_transform_edt(~covered, return_distances=False, return_indices=True)
        z = z[tuple(nearest)]
    cells = covered[:-1, :-1] & covered[:-1, 1:] & covered[1:, :-1] & covered[1:, 1:]
    return HeightField(float(lo[0]), float(lo[1]), float(spacing_m), z, None if cells.all() else cells)


def median_edge_m(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The median plan length [m] of the edges of the mesh ``vertices`` (n, 3), ``faces`` (m, 3) (1 m if all are 0)."""
    edges = np.linalg.norm(vertices[faces[:, [1, 2, 0]], :2] - vertices[faces, :2], axis=2).ravel()
    return float(np.median(edges[edges > 0])) if (edges > 0).any() else 1.0


def _joined(meshes: dict) -> tuple[np.ndarray, np.ndarray]:
    """One mesh, vertices (n, 3) and faces (m, 3), of the meshes ``{index: (vertices, faces)}``."""
    starts = np.cumsum([0] + [len(v) for v, _ in meshes.values()])
    v = np.concatenate([np.asarray(v, np.float64) for v, _ in meshes.values()])
    f = np.concatenate([np.asarray(f, np.int64) + s for (_, f), s in zip(meshes.values(), starts)])
    return v, f


def seabed_of_meshes(objects, meshes: dict) -> tuple[HeightField, dict]:
    """The height field of the panels and meshes labelled seabed (``meshes``: index in the scene's ``objects`` ->
    (vertices (n, 3), faces (m, 3)) placed in the world) and what the outputs report about it. Nodes lie every
    median edge length of the meshes; a panel's two triangles say nothing of the relief, so with a panel among them
    every :data:`PANEL_SEABED_SPACING_M` at most."""
    v, f = _joined(meshes)
    panels = [i for i in meshes if objects[i].type == "panel"]
    surveyed = [i for i in meshes if objects[i].type != "panel"]
    spacing_m = PANEL_SEABED_SPACING_M if panels else None
    if panels and surveyed:
        spacing_m = min(spacing_m, median_edge_m(*_joined({i: meshes[i] for i in surveyed})))
    try:
        hf = mesh_heightfield(v, f, spacing_m)
    except ParameterError as exc:
        first = next(iter(meshes))
        raise ConfigError(f"objects[{first}] ({objects[first].name!r}): {exc}") from None
    sources = [f"panel {objects[i].name!r}" if i in panels else objects[i].file if isinstance(objects[i].file, str)
               else "in memory" for i in meshes]
    kind = " and ".join(k for k, some in (("mesh", surveyed), ("panel", panels)) if some)
    return hf, {"source": sources, "kind": kind, "node_spacing_m": hf.spacing_m,
                "valid_cell_fraction": float(hf.valid.mean()) if hf.valid is not None else 1.0}


@kernel(nogil=True)
def _top_surface(v, f, x0, y0, s, z):
    """z (ny, nx) [m]: at each node (x0 + j s, y0 + i s), the highest of the faces ``f`` of ``v`` above it."""
    ny, nx = z.shape
    for k in range(f.shape[0]):
        a, b, c = f[k, 0], f[k, 1], f[k, 2]
        ax, ay, bx, by, cx, cy = v[a, 0], v[a, 1], v[b, 0], v[b, 1], v[c, 0], v[c, 1]
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if det == 0.0:
            continue  # vertical or degenerate in plan: no height over any node
        j0 = max(0, int(math.ceil((min(ax, bx, cx) - x0) / s - 1e-9)))
        j1 = min(nx - 1, int(math.floor((max(ax, bx, cx) - x0) / s + 1e-9)))
        i0 = max(0, int(math.ceil((min(ay, by, cy) - y0) / s - 1e-9)))
        i1 = min(ny - 1, int(math.floor((max(ay, by, cy) - y0) / s + 1e-9)))
        for i in range(i0, i1 + 1):
            py = y0 + i * s
            for j in range(j0, j1 + 1):
                px = x0 + j * s
                wb = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) / det
                wc = ((bx - ax) * (py - ay) - (px - ax) * (by - ay)) / det
                wa = 1.0 - wb - wc
                if wa >= -1e-9 and wb >= -1e-9 and wc >= -1e-9:
                    h = wa * v[a, 2] + wb * v[b, 2] + wc * v[c, 2]
                    if h > z[i, j]:
                        z[i, j] = h
