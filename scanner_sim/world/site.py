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

from muls.infra.errors import ParameterError
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
    cell_faces: np.ndarray

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
    (default :data:`TILE_M`); ``crs``: the scene's map CRS or None; ``seabed_info``: what the outputs report about a
    raster seabed, or None; ``cell_reflectance``: (ny-1, nx-1) reflectance of each cell (a class raster's), or None
    for the seabed's one material.

    A height field with gaps (``valid``) has faces only in its valid cells, numbered as the whole scene numbers
    them (:meth:`HeightField.mesh`: the lower triangles of the valid cells in row order, then the upper ones), and
    the seabed is as many smooth surfaces as the valid cells make edge-connected regions, numbered by their first
    cell in row order, as :func:`scanner_sim.world.scene.smooth_surfaces` numbers them over the whole mesh.

    Like a :class:`~scanner_sim.world.scene.Scene` it has ``heightfield``, ``objects`` (the seabed first, object 0),
    ``local_origin``, ``local_extent_m``, ``n_faces`` (the whole scene's), :meth:`surface_height` and
    :meth:`object_named`; ``vertices``, ``faces``, ``face_label`` and ``face_object`` are the objects' mesh only (the
    seabed's faces are numbered first in the whole scene, so the objects' face ranges here start at 0).
    ``face_surface[f]`` answers for faces numbered as in the whole scene. ``tile_cells``: cells per tile side.
    """

    def __init__(self, heightfield: HeightField, seabed, parts, local_origin: np.ndarray, local_extent_m: float,
                 tile_m: float | None = None, crs=None, seabed_info: dict | None = None,
                 cell_reflectance: np.ndarray | None = None):
        hf = self.heightfield = heightfield
        self.crs, self.seabed_info = crs, seabed_info  # as a Scene's: the map CRS (or None), the raster's report
        self.cell_reflectance = cell_reflectance
        ny, nx = hf.shape
        if hf.valid is None:
            self.seabed_faces, self.seabed_surfaces = 2 * (nx - 1) * (ny - 1), 1
            self._cell_rank = self._cell_surface = None
        else:
            from scipy import ndimage

            rank = np.cumsum(hf.valid.ravel(), dtype=np.int64) - 1
            #: (ny-1, nx-1) int64: each valid cell's place among the valid cells in row order (the number of its
            #: lower triangle in the whole scene); -1 or a neighbour's elsewhere (never read there).
            self._cell_rank = rank.reshape(hf.valid.shape)
            self.seabed_faces = 2 * int(rank[-1] + 1)
            regions, self.seabed_surfaces = ndimage.label(hf.valid)  # edge-connected cells: faces sharing an edge
            #: (ny-1, nx-1) int32: the smooth surface of each valid cell's faces (0 .. seabed_surfaces - 1).
            self._cell_surface = (regions - 1).astype(np.int32)
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
        seabed_surface = None if hf.valid is None else self._cell_surface[hf.valid]
        self.face_surface = _SiteSurfaces(self.seabed_faces, seabed_surface, self.seabed_surfaces,
                                          None if self.parts is None else self.parts.face_surface)

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
        valid = None if hf.valid is None else hf.valid[i0:i1, j0:j1]
        window_hf = HeightField(float(gx[0, 0]), float(gy[0, 0]), s, heights, valid)
        _, seabed_faces = window_hf.mesh()
        seabed_vertices = np.c_[gx.ravel(), gy.ravel(), heights.ravel()]
        n = seabed_faces.shape[0]
        normal, _ = face_geometry(seabed_vertices - self.local_origin, seabed_faces)
        nx = hf.shape[1]
        if valid is None:
            rows, cols = np.divmod(np.arange((i1 - i0) * (j1 - j0)), j1 - j0)
            cell_faces = (rows + i0) * (nx - 1) + (cols + j0)
            surface = np.zeros(n, np.int32)
        else:
            cell_faces = self._cell_rank[i0:i1, j0:j1][valid]
            surface = np.tile(self._cell_surface[i0:i1, j0:j1][valid], 2)
        reflectance = (np.full(n, self.seabed_reflectance) if self.cell_reflectance is None else
                       np.tile(self.cell_reflectance[i0:i1, j0:j1][valid if valid is not None else slice(None)]
                               .ravel(), 2))
        seabed = dataclasses.replace(self.objects[0], face_start=0, face_stop=n)
        o = self.parts
        if o is None:
            return WindowScene(seabed_vertices, seabed_faces, normal, reflectance,
                               np.full(n, self.seabed_label, np.int16), np.zeros(n, np.int32), surface,
                               self.local_origin, self.local_extent_m, window_hf, [seabed], (j0, j1, i0, i1),
                               cell_faces)
        others = [dataclasses.replace(x, face_start=x.face_start + n, face_stop=x.face_stop + n)
                  for x in self.objects[1:]]
        return WindowScene(
            np.concatenate([seabed_vertices, o.vertices]), np.concatenate([seabed_faces, o.faces + len(seabed_vertices)]),
            np.concatenate([normal, o.face_normal]), np.r_[reflectance, o.face_reflectance],
            np.r_[np.full(n, self.seabed_label, np.int16), o.face_label], np.r_[np.zeros(n, np.int32), o.face_object + 1],
            np.r_[surface, o.face_surface + self.seabed_surfaces], self.local_origin, self.local_extent_m, window_hf,
            [seabed, *others], (j0, j1, i0, i1), cell_faces)

    def site_faces(self, window: WindowScene, tri: np.ndarray) -> np.ndarray:
        """Faces ``tri`` (k,) of ``window`` numbered as in the whole scene (the seabed's valid cells first, in
        :meth:`HeightField.mesh` order, then the objects)."""
        cells = window.cell_faces.shape[0]
        tri = np.asarray(tri, np.int64)
        if not cells:
            return tri + self.seabed_faces
        upper, cell = np.divmod(np.minimum(tri, 2 * cells - 1), cells)
        seabed = upper * (self.seabed_faces // 2) + window.cell_faces[cell]
        return np.where(tri < 2 * cells, seabed, tri - 2 * cells + self.seabed_faces)


def tiled(heightfield: HeightField) -> bool:
    """Whether a seabed is tiled: more triangles than :data:`TILED_ABOVE_TRIANGLES`."""
    ny, nx = heightfield.shape
    return 2 * (nx - 1) * (ny - 1) > TILED_ABOVE_TRIANGLES


class _SiteSurfaces:
    """``face_surface`` of a :class:`SiteScene`, indexed by faces numbered as in the whole scene: the seabed's
    surfaces first (``seabed`` (n_c,) int32: the surface of each valid cell in row order, or None where the seabed
    is one surface, 0), the objects' surfaces follow (those of ``parts`` (n,) int32, plus ``seabed_surfaces``)."""

    def __init__(self, seabed_faces: int, seabed: np.ndarray | None, seabed_surfaces: int, parts: np.ndarray | None):
        self.seabed_faces, self.seabed, self.seabed_surfaces, self.parts = seabed_faces, seabed, seabed_surfaces, parts

    def __getitem__(self, tri) -> np.ndarray:
        tri = np.asarray(tri, np.int64)
        on_seabed = tri < self.seabed_faces
        if self.seabed is None:
            seabed = np.zeros(tri.shape, np.int32)
        else:
            seabed = self.seabed[np.clip(tri, 0, self.seabed_faces - 1) % (self.seabed_faces // 2)]
        if self.parts is None:
            return seabed.astype(np.int32)
        rest = np.clip(tri - self.seabed_faces, 0, max(0, len(self.parts) - 1))
        return np.where(on_seabed, seabed, self.parts[rest] + self.seabed_surfaces).astype(np.int32)
