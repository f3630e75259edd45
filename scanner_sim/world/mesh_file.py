"""A ``mesh`` object's file read and checked: trimesh loads it, after its size is checked against the memory a pass
may use (:mod:`scanner_sim.world.mesh_size`) and before its vertices, faces and PLY header are checked, so that a
bad file is refused in one line naming the object and the file."""

from __future__ import annotations

import numpy as np

from scanner_sim.config import ConfigError, MeshObject
from scanner_sim.world.facets import nondegenerate
from scanner_sim.world.ply_header import ply_element_counts


def load_mesh_file(obj: MeshObject, index: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) float64 and faces (m, 3) int64 of a ``mesh`` object's file, as the file gives them
    (trimesh's usual processing applied: duplicate vertices merged).

    Raises :class:`ConfigError` naming the object (``objects[index]`` and its name) and the file when trimesh
    cannot read it, or it holds no triangles, vertices that are not finite, faces that refer to missing
    vertices, or only degenerate (zero-area) triangles. trimesh's own loading would silently drop the
    triangles with NaN corners, and the first three errors would otherwise surface as a traceback.
    """
    import trimesh

    where = f"objects[{index}].file = {obj.file!r} (object {obj.name!r})"
    if obj.resolved_path is not None:
        _check_mesh_size(obj.resolved_path, where)
    try:
        mesh = obj.file if obj.resolved_path is None else trimesh.load(obj.resolved_path, force="mesh", process=False)
        v = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), float)
        f = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    except Exception as exc:  # trimesh raises whatever its parser meets: ValueError, IndexError, KeyError...
        detail = " ".join(str(exc).split())[:120]
        raise ConfigError(f"{where}: not a mesh file trimesh can read ({type(exc).__name__}: {detail})") from None
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or v.ndim != 2 or v.shape[1] != 3:
        raise ConfigError(f"{where}: no triangles (an empty file, or not a mesh format trimesh recognises by its "
                          "suffix)")
    _check_ply_whole(obj, where, len(v), len(f))
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise ConfigError(f"{where}: {int(bad.sum()):,} of {len(v):,} vertices are not finite (NaN or infinite), "
                          f"the first is vertex {int(np.flatnonzero(bad)[0])}")
    if not np.issubdtype(f.dtype, np.integer) or f.min() < 0 or f.max() >= len(v):
        i = int(np.flatnonzero(((f < 0) | (f >= len(v))).any(axis=1))[0]) if np.issubdtype(f.dtype, np.integer) else 0
        raise ConfigError(f"{where}: face {i} refers to vertex {f[i].tolist()}, but the file has {len(v):,} vertices "
                          f"(0 to {len(v) - 1})")
    f = f.astype(np.int64)
    with np.errstate(over="ignore", invalid="ignore"):  # huge coordinates are judged once placed (build_scene)
        some_area = nondegenerate(v, f).any()
    if not some_area:
        raise ConfigError(f"{where}: all {len(f):,} triangles are degenerate (zero area)")
    mesh = trimesh.Trimesh(v, f, process=True)
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def _check_mesh_size(path, where: str) -> None:
    """Refuse a mesh file whose triangles, counted before loading (:func:`~scanner_sim.world.mesh_size.declared_triangles`),
    would need more memory to load than a pass may plan on (80 % of what is available)."""
    from muls.infra.memory import MEMORY_SHARE, available_memory_bytes, gb
    from scanner_sim.world.mesh_size import MESH_BYTES_PER_TRIANGLE, declared_triangles

    try:
        triangles = declared_triangles(path)
    except OSError:
        return  # unreadable: trimesh's own refusal names it
    available = available_memory_bytes()
    if triangles is None or available is None:
        return
    need, budget = triangles * MESH_BYTES_PER_TRIANGLE, MEMORY_SHARE * available
    if need > budget:
        raise ConfigError(f"{where}: {triangles:,} triangles would need about {gb(need)} of memory to load, more than "
                          f"the {gb(budget)} a pass may use ({MEMORY_SHARE:.0%} of the {gb(available)} available); at "
                          f"most {int(budget // MESH_BYTES_PER_TRIANGLE):,} triangles on this machine (decimate the "
                          "mesh, e.g. with MeshLab's quadric edge collapse)")


def _check_ply_whole(obj: MeshObject, where: str, n_vertices: int, n_faces: int) -> None:
    """Refuse a PLY file that holds fewer vertices or faces than its header promises (a copy cut short): trimesh
    reads an ASCII one as the lines it holds, silently. (A face may be cut into triangles, so more faces is fine.)"""
    if not str(obj.resolved_path).lower().endswith(".ply"):
        return
    promised = ply_element_counts(obj.resolved_path) or {}
    for element, plural, held in (("vertex", "vertices", n_vertices), ("face", "faces", n_faces)):
        if held < promised.get(element, 0):
            raise ConfigError(f"{where}: truncated: its header promises {promised[element]:,} {plural}, the file "
                              f"holds {held:,} (a copy cut short?)")
