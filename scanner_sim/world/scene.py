"""Scenes: object generators and the combined mesh the rays see.

A :class:`Scene` is one triangle mesh (world coordinates, float64) with per-triangle object id, smooth surface,
class label and reflectance, the seabed's height field for fast height queries, and a local origin: the mesh is shifted
by ``local_origin`` before it reaches Embree in float32, and rays are shifted the same way, so a scene in
UTM coordinates ranges as accurately as one at the origin (docs/design.md#frames).

:func:`build_scene` builds the seabed (procedural, a raster's, or the meshes labelled seabed) and each object
through its type's builder (:data:`scanner_sim.world.objects.OBJECT_BUILDERS`); the seabeds of rasters and meshes
live in :mod:`scanner_sim.world.raster` and :mod:`scanner_sim.world.mesh_seabed`, a mesh object's file is read in
:mod:`scanner_sim.world.mesh_file`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config import ConfigError, SceneConfig, reflectance_of
from scanner_sim.config.crs import to_crs
from scanner_sim.config.materials import LABELS
from scanner_sim.config.raster_seabed import RasterSeabedConfig
from scanner_sim.world.facets import DEGENERATE_AREA, face_geometry, mesh_scale
from scanner_sim.world.mesh_seabed import seabed_of_meshes
from scanner_sim.world.objects import object_mesh, panel_mesh, seabed_object_mesh
from scanner_sim.world.raster import load_raster_seabed, plan_bounds
from scanner_sim.world.site import SiteScene, tiled
from scanner_sim.world.terrain import HeightField, generate_heightfield, rock_meshes

#: Largest world coordinate [m]: beyond any place on Earth in a projected CRS (UTM northings reach 1e7 m);
#: larger values are a unit slip, and overflow the float arithmetic of normals and ray casting.
MAX_COORDINATE_M = 1e8


@dataclass(frozen=True)
class SceneObject:
    """One object of the scene: its index is ``object_id``; faces [start, stop) of the combined mesh."""

    object_id: int
    name: str
    kind: str
    label: int
    reflectance: float
    face_start: int
    face_stop: int
    centreline: np.ndarray | None = None  # (n, 3) world [m] for cables and pipelines, else None


@dataclass(frozen=True)
class Part:
    """A mesh to add to a scene: vertices (n, 3) float64 world [m], faces (m, 3) int."""

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    label: int
    reflectance: float
    centreline: np.ndarray | None = None
    one_surface: bool = False  # one smooth surface whatever its creases (the seabed's height field)
    face_reflectance: np.ndarray | None = None  # (m,) per face, in place of ``reflectance`` (a class raster's)


class Scene:
    """The combined triangle mesh with per-triangle attributes.

    vertices (n_v, 3) float64 world [m]; faces (n_f, 3) int64; face_object (n_f,) int32; face_surface (n_f,)
    int32 (:func:`smooth_surfaces`: which smooth surface of the scene the face belongs to); face_label (n_f,)
    int16 (LAS code); face_reflectance (n_f,) float64; face_normal (n_f, 3) float64 unit (right-hand winding);
    local_origin (3,) float64 world [m]; heightfield: the seabed's, or None; objects: list of SceneObject;
    seabed_info: what the outputs report about a seabed read from a raster or a mesh (JSON-ready), or None;
    crs: the :class:`pyproj.CRS` whose map coordinates the world frame is in, or None (a local frame).
    """

    def __init__(self, parts: list[Part], heightfield: HeightField | None = None,
                 local_origin: np.ndarray | None = None, crs=None, seabed_info: dict | None = None):
        if not parts:
            raise ParameterError("scene: no geometry (give a seabed or at least one object)")
        verts = [np.asarray(p.vertices, float) for p in parts]
        starts = np.cumsum([0] + [len(v) for v in verts])
        faces = np.concatenate([np.asarray(p.faces, np.int64) + starts[i] for i, p in enumerate(parts)])
        part = np.concatenate([np.full(len(p.faces), i, np.int32) for i, p in enumerate(parts)])
        starts_f = np.cumsum([0] + [len(p.faces) for p in parts])
        self.vertices = np.concatenate(verts)
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        # Local origin: the bounding box centre rounded to whole metres (a readable number).
        self.local_origin = np.round(0.5 * (lo + hi)) if local_origin is None else np.asarray(local_origin, float)
        local = self.vertices - self.local_origin
        normal, area2 = face_geometry(local, faces)
        scale = np.array([mesh_scale(v) for v in verts])
        keep = area2 > DEGENERATE_AREA * scale[part] ** 2  # degenerate triangles go: Embree and normals need area
        self.faces, part, self.face_normal = faces[keep], part[keep], normal[keep]
        self.face_object = part
        self.face_surface = smooth_surfaces(self.faces, self.face_normal, np.array([p.one_surface for p in parts])[part])
        self.face_label = np.array([p.label for p in parts], np.int16)[part]
        self.face_reflectance = np.array([p.reflectance for p in parts], float)[part]
        for i, p in enumerate(parts):
            if p.face_reflectance is not None:
                self.face_reflectance[part == i] = np.asarray(p.face_reflectance, float)[keep[starts_f[i]:starts_f[i + 1]]]
        ends = np.cumsum(np.bincount(part, minlength=len(parts)))
        self.objects = [SceneObject(i, p.name, p.kind, p.label, p.reflectance, int(ends[i - 1]) if i else 0,
                                    int(ends[i]), p.centreline) for i, p in enumerate(parts)]
        self.heightfield = heightfield
        self.crs = crs
        self.seabed_info = seabed_info
        self.local_extent_m = float(np.abs(local).max())

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def surface_height(self, x_m, y_m) -> np.ndarray:
        """Seabed z [m] at world (x, y) from the height field (rocks and objects not included)."""
        if self.heightfield is None:
            raise ParameterError("scene has no seabed: surface_height needs a seabed section")
        return self.heightfield.height(x_m, y_m)

    def object_named(self, name: str) -> SceneObject:
        for o in self.objects:
            if o.name == name:
                return o
        raise ParameterError(f"object = {name!r}: the scene has {', '.join(o.name for o in self.objects)}")


#: [deg] Two faces that share an edge belong to one smooth surface when their normals differ by less than this
#: (:func:`smooth_surfaces`). The tessellations of curved surfaces the scenes build stay one surface (the 8-sided
#: tether 45 deg, the 12-sided cable 30 deg, the 32-section mines 11.25 deg, the rocks under 52 deg), while a
#: step's riser, a box's edge or a cylinder's rim (90 deg) part two surfaces. An assumption (docs/assumptions.md).
SURFACE_CREASE_DEG = 60.0


def smooth_surfaces(faces: np.ndarray, normal: np.ndarray, one_surface: np.ndarray) -> np.ndarray:
    """(n_f,) int32: the smooth surface of each face (n_f, 3) int of unit ``normal`` (n_f, 3), numbered from 0: the
    faces joined, edge by shared edge, where the two normals differ by less than :data:`SURFACE_CREASE_DEG`, or
    whatever they differ by where ``one_surface`` (n_f,) bool holds for the faces (a height field: one value of z
    over each x, y, with neither riser nor overhang however rough, is one surface).

    Faces join only across an edge they share by vertex index (the generators and the mesh loader, which merges
    duplicate vertices, give them so), so two objects never share a surface. The normals are compared as wound:
    where a mesh's winding flips between two faces they stay two surfaces, which only makes the truth take the
    ranged face's own plane (survey.georeference), never another surface's."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = faces.shape[0]
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)  # (3 n_f, 2): face k's edges at 3k..3k+2
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    same = np.all(edges[order[1:]] == edges[order[:-1]], axis=1)  # consecutive copies of one edge
    a, b = order[:-1][same] // 3, order[1:][same] // 3
    smooth = one_surface[a] | (np.einsum("ij,ij->i", normal[a], normal[b]) > math.cos(math.radians(SURFACE_CREASE_DEG)))
    graph = coo_matrix((np.ones(np.count_nonzero(smooth), np.int8), (a[smooth], b[smooth])), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int32)


def build_scene(config, tile_m: float | None = None) -> Scene:
    """Build the :class:`Scene` of a :class:`scanner_sim.config.SceneConfig` (deterministic from its seeds); a seabed
    (procedural or a raster's) of more than :data:`~scanner_sim.world.site.TILED_ABOVE_TRIANGLES` triangles gives a
    :class:`SiteScene` instead, in tiles of about :data:`scanner_sim.world.site.TILE_M`, or of ``tile_m`` [m] when
    given (any such seabed then)."""
    if tile_m is not None and not tile_m > 0:
        raise ParameterError(f"tile_m = {tile_m!r}: must be a tile's side in metres, > 0 (or None: tiled by size)")
    if not isinstance(config, SceneConfig):
        raise TypeError(f"config must be a SceneConfig (scanner_sim.load_scene(name_or_path) gives one), not "
                        f"{type(config).__name__} {config!r:.60}")
    parts: list[Part] = []
    hf, info = None, None
    sb = config.seabed
    cell_reflectance = None
    if isinstance(sb, RasterSeabedConfig):
        raster = load_raster_seabed(sb, plan_bounds(config), config.crs)
        hf, info, cell_reflectance = raster.heightfield, raster.info, raster.cell_reflectance
    elif sb is not None:
        rng = np.random.default_rng(sb.seed)
        hf = generate_heightfield(sb.center_m, sb.size_m, sb.resolution_m, sb.depth_m, sb.relief.rms_m,
                                  sb.relief.wavelength_m, sb.relief.hurst, sb.ripples.amplitude_m,
                                  sb.ripples.wavelength_m, sb.ripples.crest_deg, sb.ripples.sinuosity, rng)
        rk = sb.rocks
        if rk.count:
            rocks = rock_meshes(hf, rk.count, (rk.radius_min_m, rk.radius_max_m), rng)
            v = np.concatenate([r[0] for r in rocks])
            offsets = np.cumsum([0] + [len(r[0]) for r in rocks[:-1]])
            f = np.concatenate([r[1] + o for r, o in zip(rocks, offsets)])
            parts.append(Part("rocks", "rocks", v, f, LABELS[rk.label], reflectance_of(rk)))
    site = hf is not None and (bool(tile_m) or tiled(hf))
    if hf is not None and not site:  # the seabed's mesh, part 0 (a site meshes it in windows as the pass goes)
        v, f = hf.mesh()
        per_face = None if cell_reflectance is None else np.tile(cell_reflectance.ravel(), 2)[
            np.tile(hf.valid.ravel(), 2) if hf.valid is not None else slice(None)]
        parts.insert(0, Part("seabed", "seabed", v, f, LABELS[sb.label], reflectance_of(sb), one_surface=True,
                             face_reflectance=per_face))

    seabed_meshes = {} if hf is not None else {i: seabed_object_mesh(config.objects[i], i)
                                                for i in config.seabed_objects}
    if seabed_meshes:
        hf, info = seabed_of_meshes(config.objects, seabed_meshes)
    for index, obj in enumerate(config.objects):
        refl, label = reflectance_of(obj), LABELS[obj.label]
        v, f, centreline = (*seabed_meshes[index], None) if index in seabed_meshes else object_mesh(obj, index, hf)
        if not (np.abs(v) <= MAX_COORDINATE_M).all():  # NaN included
            raise ConfigError(f"objects[{index}] ({obj.name!r}): its sizes and position give coordinates that are not "
                              f"finite or beyond +-{MAX_COORDINATE_M:.0e} m; check them (metres)")
        kind = "seabed" if index in seabed_meshes else obj.type  # a mesh seabed is the background, as the procedural
        parts.append(Part(obj.name, kind, v, f, label, refl, centreline, one_surface=index in seabed_meshes))
    if site:
        return site_scene(hf, SceneObject(0, "seabed", "seabed", LABELS[sb.label], reflectance_of(sb), 0, 0), parts,
                          tile_m, crs=to_crs(config.crs), seabed_info=info, cell_reflectance=cell_reflectance)
    return Scene(parts, hf, crs=to_crs(config.crs), seabed_info=info)


def site_scene(heightfield: HeightField, seabed: SceneObject, parts: list[Part], tile_m: float | None = None,
               crs=None, seabed_info: dict | None = None, cell_reflectance: np.ndarray | None = None):
    """The :class:`scanner_sim.world.site.SiteScene` of a seabed (``seabed``: object 0, no faces of its own) and the
    other ``parts``, in the frame the whole :class:`Scene` of them would have (its local origin: the bounding box
    centre in whole metres; its extent); ``crs`` and ``seabed_info`` as :class:`Scene`'s; ``cell_reflectance``
    (ny-1, nx-1): each seabed cell's (a class raster's), or None."""
    x_lo, x_hi, y_lo, y_hi = heightfield.extent_m
    lo = np.array([x_lo, y_lo, heightfield.heights_m.min()])
    hi = np.array([x_hi, y_hi, heightfield.heights_m.max()])
    for p in parts:
        lo, hi = np.minimum(lo, p.vertices.min(axis=0)), np.maximum(hi, p.vertices.max(axis=0))
    origin = np.round(0.5 * (lo + hi))
    extent = float(np.abs(np.r_[lo - origin, hi - origin]).max())
    return SiteScene(heightfield, seabed, Scene(parts, None, origin) if parts else None, origin, extent, tile_m,
                     crs=crs, seabed_info=seabed_info, cell_reflectance=cell_reflectance)


def plate_scene(distance_m: float, size_m: float = 20.0, center_xy_m=(0.0, 0.0), origin_m=(0.0, 0.0, 0.0),
                reflectance: float = 0.1) -> Scene:
    """A square plate facing +z, ``distance_m`` below ``origin_m`` (the overlap check's target)."""
    o = np.asarray(origin_m, float)
    v, f = panel_mesh(o + [center_xy_m[0], center_xy_m[1], -distance_m], (size_m, size_m), (0, 0, 1), (0, 1, 0))
    return Scene([Part("plate", "panel", v, f, LABELS["panel"], reflectance)])
