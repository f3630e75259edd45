"""A site-scale scene: the seabed kept as its height field (one array of heights) and meshed only in windows of
square tiles around where the pass's rays go, the other objects meshed whole.

A :class:`SiteScene` is what :func:`scanner_sim.world.scene.build_scene` gives for a seabed of more than
:data:`TILED_ABOVE_TRIANGLES` triangles (docs/design.md#site-scale-scenes). It has the
local origin, local extent, objects, labels and surfaces the whole :class:`~scanner_sim.world.scene.Scene` would
have; :meth:`SiteScene.window` builds the mesh of a rectangle of tiles (its seabed triangles, then every other
object) as a :class:`WindowScene`, each face with the very normal, material, label, object and surface it has in
the whole scene, so a ray cast into a window that holds its whole path meets what it would meet in the whole
scene, bit for bit.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from muls.errors import ParameterError
from scanner_sim.rays.seabed_grid import COARSE_CELL_M, SUPER_CELL_M
from scanner_sim.world.facets import face_geometry
from scanner_sim.world.terrain import HeightField

#: A seabed of more triangles than this is tiled (a :class:`SiteScene`); smaller scenes are one mesh. Two million
#: triangles hold about 0.6 GB of mesh, face attributes and BVH at once (docs/design.md#site-scale-scenes).
TILED_ABOVE_TRIANGLES = 2_000_000

#: [m] Side of a tile, about: rounded up to whole blocks of the proof grid's super cells (so that a window's proof
#: grid is the whole scene's, cut out). 8 m at 0.25 m cells is 2,048 triangles a tile.
TILE_M = 8.0


@dataclass(frozen=True)
class WindowScene:
    """The mesh of a window of a :class:`SiteScene`, with what the ray stage reads of a
    :class:`~scanner_sim.world.scene.Scene`: vertices (n_v, 3) float64 world [m], faces (n_f, 3) int64 (the window's
    seabed cells in :meth:`HeightField.mesh` order, then the objects), per-face normal, reflectance, label, object
    and surface, the site's local origin and extent, the window's height field and objects (face ranges in the
    window). ``cells``: (j0, j1, i0, i1), the window's cell columns j0 .. j1 - 1 and rows i0 .. i1 - 1 of the site."""

    vertices: np.ndarray
    faces: np.ndarray
    face_normal: np.ndarray
    face_reflectance: np.ndarray
    face_label: np.ndarray
    face_object: np.ndarray
    face_surface: np.ndarray
    local_origin: np.ndarray
    local_extent_m: float
    heightfield: HeightField
    objects: list
    cells: tuple[int, int, int, int]

    @property
    def n_faces(self) -> int:
        return int(self.face_object.shape[0])

    def without_mesh(self) -> WindowScene:
        """This window without its vertices and faces (emptied): what the ray stage reads once the window's caster
        and proof grid are built, which hold the mesh themselves (float32, local)."""
        return dataclasses.replace(self, vertices=np.zeros((0, 3)), faces=np.zeros((0, 3), np.int64))


class SiteScene:
    """A scene whose seabed is tiled: the height field whole, the other parts as one mesh. ``seabed``: the seabed's
    :class:`~scanner_sim.world.scene.SceneObject` (object 0); ``parts``: a :class:`~scanner_sim.world.scene.Scene` of
    the other parts in the site's frame, or None; ``local_origin`` (3,) [m] and ``local_extent_m``: the whole
    scene's (:func:`scanner_sim.world.scene.site_scene` builds them all); ``tile_m``: about a tile's side [m]
    (default :data:`TILE_M`); ``crs``: the scene's map CRS or None.

    Like a :class:`~scanner_sim.world.scene.Scene` it has ``heightfield``, ``objects`` (the seabed first, object 0),
    ``local_origin``, ``local_extent_m``, ``n_faces`` (the whole scene's), :meth:`surface_height` and
    :meth:`object_named`; ``vertices``, ``faces``, ``face_label`` and ``face_object`` are the objects' mesh only (the
    seabed's faces are numbered first in the whole scene, so the objects' face ranges here start at 0).
    ``face_surface[f]`` answers for faces numbered as in the whole scene. ``tile_cells``: cells per tile side.
    """

    def __init__(self, heightfield: HeightField, seabed, parts, local_origin: np.ndarray, local_extent_m: float,
                 tile_m: float | None = None, crs=None):
        hf = self.heightfield = heightfield
        self.crs, self.seabed_info = crs, None  # as a Scene's: the map CRS (or None); a procedural seabed has no info
        ny, nx = hf.shape
        self.seabed_faces = 2 * (nx - 1) * (ny - 1)
        self.local_origin, self.local_extent_m, self.parts = np.asarray(local_origin, float), local_extent_m, parts
        z32 = np.float32(hf.heights_m - self.local_origin[2])
        z_top, z_low = float(z32.max()), float(z32.min())
        if self.parts is not None:
            p32 = np.float32(self.parts.vertices[:, 2] - self.local_origin[2])
            z_top, z_low = max(z_top, float(p32.max())), min(z_low, float(p32.min()))
        #: [m] local: above z_top there is nothing (the proof grid's ``z_top`` less its clearance), below z_low nothing.
        self.z_top_local, self.z_low_local = z_top, z_low
        k = max(1, round(COARSE_CELL_M / hf.spacing_m))
        block = k * max(1, round(SUPER_CELL_M / (k * hf.spacing_m)))  # cells per super cell of the proof grid
        self.tile_cells = block * max(1, math.ceil((tile_m or TILE_M) / (block * hf.spacing_m)))
        t = self.tile_cells
        pad = np.full((-(-(ny - 1) // t) * t, -(-(nx - 1) // t) * t), np.inf)  # each tile's lowest node
        pad[:ny - 1, :nx - 1] = np.minimum(np.minimum(hf.heights_m[:-1, :-1], hf.heights_m[1:, :-1]),
                                           np.minimum(hf.heights_m[:-1, 1:], hf.heights_m[1:, 1:]))
        #: (tiles y, tiles x) [m] local: the lowest seabed node of each tile (objects: ``z_low_local``).
        self.tile_low = pad.reshape(pad.shape[0] // t, t, pad.shape[1] // t, t).min(axis=(1, 3)) - self.local_origin[2]
        others = [] if parts is None else [dataclasses.replace(o, object_id=o.object_id + 1) for o in parts.objects]
        self.objects = [seabed, *others]
        self.seabed_label, self.seabed_reflectance = int(seabed.label), float(seabed.reflectance)
        empty = np.zeros((0, 3))
        self.vertices = empty if self.parts is None else self.parts.vertices
        self.faces = empty.astype(np.int64) if self.parts is None else self.parts.faces
        self.face_label = np.zeros(0, np.int16) if self.parts is None else self.parts.face_label
        self.face_object = np.zeros(0, np.int32) if self.parts is None else self.parts.face_object + 1
        self.face_surface = _SiteSurfaces(self.seabed_faces, None if self.parts is None else self.parts.face_surface)

    @property
    def n_faces(self) -> int:
        return self.seabed_faces + (0 if self.parts is None else self.parts.n_faces)

    def surface_height(self, x_m, y_m) -> np.ndarray:
        """Seabed z [m] at world (x, y) from the height field (rocks and objects not included)."""
        return self.heightfield.height(x_m, y_m)

    def object_named(self, name: str):
        for o in self.objects:
            if o.name == name:
                return o
        raise ParameterError(f"object = {name!r}: the scene has {', '.join(o.name for o in self.objects)}")

    def window(self, j0: int, j1: int, i0: int, i1: int) -> WindowScene:
        """The mesh of cell columns j0 .. j1 - 1 and rows i0 .. i1 - 1 (node columns j0 .. j1, rows i0 .. i1) and of
        every other object, each face as the whole scene has it (vertices at the very coordinates, normals by the
        same arithmetic)."""
        hf, s = self.heightfield, self.heightfield.spacing_m
        heights = hf.heights_m[i0:i1 + 1, j0:j1 + 1]
        # Node positions as HeightField.mesh computes them over the whole grid (x0 + s j), not from the window's
        # corner, so the window's vertices are the whole scene's to the bit.
        gx, gy = np.meshgrid(hf.x0_m + s * np.arange(j0, j1 + 1), hf.y0_m + s * np.arange(i0, i1 + 1))
        window_hf = HeightField(float(gx[0, 0]), float(gy[0, 0]), s, heights)
        _, seabed_faces = window_hf.mesh()
        seabed_vertices = np.c_[gx.ravel(), gy.ravel(), heights.ravel()]
        n = seabed_faces.shape[0]
        normal, _ = face_geometry(seabed_vertices - self.local_origin, seabed_faces)
        seabed = dataclasses.replace(self.objects[0], face_start=0, face_stop=n)
        o = self.parts
        if o is None:
            return WindowScene(seabed_vertices, seabed_faces, normal, np.full(n, self.seabed_reflectance),
                               np.full(n, self.seabed_label, np.int16), np.zeros(n, np.int32), np.zeros(n, np.int32),
                               self.local_origin, self.local_extent_m, window_hf, [seabed], (j0, j1, i0, i1))
        others = [dataclasses.replace(x, face_start=x.face_start + n, face_stop=x.face_stop + n)
                  for x in self.objects[1:]]
        return WindowScene(
            np.concatenate([seabed_vertices, o.vertices]), np.concatenate([seabed_faces, o.faces + len(seabed_vertices)]),
            np.concatenate([normal, o.face_normal]), np.r_[np.full(n, self.seabed_reflectance), o.face_reflectance],
            np.r_[np.full(n, self.seabed_label, np.int16), o.face_label], np.r_[np.zeros(n, np.int32), o.face_object + 1],
            np.r_[np.zeros(n, np.int32), o.face_surface + 1], self.local_origin, self.local_extent_m, window_hf,
            [seabed, *others], (j0, j1, i0, i1))

    def site_faces(self, window: WindowScene, tri: np.ndarray) -> np.ndarray:
        """Faces ``tri`` (k,) of ``window`` numbered as in the whole scene (the seabed's cells first, in
        :meth:`HeightField.mesh` order, then the objects)."""
        j0, j1, i0, i1 = window.cells
        nx = self.heightfield.shape[1]
        cells = (j1 - j0) * (i1 - i0)
        tri = np.asarray(tri, np.int64)
        upper, cell = np.divmod(tri, cells)
        i, j = np.divmod(cell, j1 - j0)
        seabed = upper * (self.seabed_faces // 2) + (i + i0) * (nx - 1) + (j + j0)
        return np.where(tri < 2 * cells, seabed, tri - 2 * cells + self.seabed_faces)


def tiled(heightfield: HeightField) -> bool:
    """Whether a seabed is tiled: more triangles than :data:`TILED_ABOVE_TRIANGLES`."""
    ny, nx = heightfield.shape
    return 2 * (nx - 1) * (ny - 1) > TILED_ABOVE_TRIANGLES


class _SiteSurfaces:
    """``face_surface`` of a :class:`SiteScene`, indexed by faces numbered as in the whole scene: the seabed is one
    surface (0), the objects' surfaces follow (those of ``parts`` (n,) int32, plus one)."""

    def __init__(self, seabed_faces: int, parts: np.ndarray | None):
        self.seabed_faces, self.parts = seabed_faces, parts

    def __getitem__(self, tri) -> np.ndarray:
        tri = np.asarray(tri, np.int64)
        if self.parts is None:
            return np.zeros(tri.shape, np.int32)
        rest = np.clip(tri - self.seabed_faces, 0, max(0, len(self.parts) - 1))
        return np.where(tri < self.seabed_faces, 0, self.parts[rest] + 1).astype(np.int32)
