"""Scenes: object generators and the combined mesh the rays see.

A :class:`Scene` is one triangle mesh (world coordinates, float64) with per-triangle object id, smooth surface,
class label and reflectance, the seabed's height field for fast height queries, and a local origin: the mesh is shifted
by ``local_origin`` before it reaches Embree in float32, and rays are shifted the same way, so a scene in
UTM coordinates ranges as accurately as one at the origin (docs/design.md#frames).

Past 450 lines as one module: the object generators and the build that places them share its helpers (rotation,
ground level, the degenerate-face test) and the mesh loader's checks; the seabeds of rasters and meshes live in
:mod:`scanner_sim.world.raster` and :mod:`scanner_sim.world.mesh_seabed`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config import (
    CableObject,
    ConeMineObject,
    ConfigError,
    CylinderMineObject,
    MeshObject,
    MooredMineObject,
    PanelObject,
    SceneConfig,
    reflectance_of,
)
from scanner_sim.config.crs import to_crs
from scanner_sim.config.materials import LABELS
from scanner_sim.config.raster_seabed import RasterSeabedConfig
from scanner_sim.world.facets import face_geometry
from scanner_sim.world.mesh_seabed import seabed_of_meshes
from scanner_sim.world.ply_header import ply_element_counts
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
        scale = np.array([_mesh_scale(v) for v in verts])
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

#: A triangle with twice its area below this times the square of its mesh's size is degenerate.
DEGENERATE_AREA = 1e-14

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


def _mesh_scale(v: np.ndarray) -> float:
    return max(1e-12, float(np.ptp(v, axis=0).max()) if len(v) else 1.0)


def _nondegenerate(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(m,) bool: the faces f (m, 3) of vertices v (n, 3) that are not degenerate."""
    return face_geometry(np.ascontiguousarray(v, np.float64), np.ascontiguousarray(f, np.int64))[1] > (
        DEGENERATE_AREA * _mesh_scale(v) ** 2)


# ------------------------------------------------------------------------------------------------------
# Object generators: each returns (vertices (n, 3) float64 world, faces (m, 3) int64), outward normals.
# ------------------------------------------------------------------------------------------------------

def frustum(bottom_radius_m: float, top_radius_m: float, height_m: float, sections: int = 32):
    """Closed truncated cone (cylinder when the radii are equal) on the z axis, base at z = 0."""
    phi = 2.0 * np.pi * np.arange(sections) / sections
    ring = np.c_[np.cos(phi), np.sin(phi)]
    bottom = np.c_[bottom_radius_m * ring, np.zeros(sections)]
    top = np.c_[top_radius_m * ring, np.full(sections, height_m)]
    verts = np.vstack([bottom, top, [[0.0, 0.0, 0.0], [0.0, 0.0, height_m]]])
    i = np.arange(sections)
    j = (i + 1) % sections
    side = np.r_[np.c_[i, j, j + sections], np.c_[i, j + sections, i + sections]]
    cb, ct = 2 * sections, 2 * sections + 1
    caps = np.r_[np.c_[np.full(sections, cb), j, i], np.c_[np.full(sections, ct), i + sections, j + sections]]
    return verts, np.r_[side, caps].astype(np.int64)


def tube(centreline: np.ndarray, radius_m: float, sides: int = 12):
    """Closed tube of ``radius_m`` swept along ``centreline`` (n, 3) [m]; frames keep one axis horizontal."""
    c = np.asarray(centreline, float)
    t = np.gradient(c, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    side = np.cross([0.0, 0.0, 1.0], t)
    bad = np.linalg.norm(side, axis=1) < 1e-9
    side[bad] = np.cross([1.0, 0.0, 0.0], t[bad])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    up = np.cross(t, side)
    phi = 2.0 * np.pi * np.arange(sides) / sides
    ring = (np.cos(phi)[None, :, None] * side[:, None, :] + np.sin(phi)[None, :, None] * up[:, None, :])
    n = len(c)
    verts = (c[:, None, :] + radius_m * ring).reshape(-1, 3)
    k = np.arange(n - 1)[:, None] * sides
    i = np.arange(sides)[None, :]
    j = (i + 1) % sides
    a, b, cc, d = (k + i), (k + j), (k + sides + i), (k + sides + j)
    faces = np.r_[np.c_[a.ravel(), cc.ravel(), b.ravel()], np.c_[b.ravel(), cc.ravel(), d.ravel()]]
    start, end = len(verts), len(verts) + 1
    verts = np.vstack([verts, c[0], c[-1]])
    ii = np.arange(sides)
    jj = (ii + 1) % sides
    caps = np.r_[np.c_[np.full(sides, start), jj, ii], np.c_[np.full(sides, end), (n - 1) * sides + ii,
                                                               (n - 1) * sides + jj]]
    faces = np.r_[faces, caps]
    # Orient outward: the ring winding above is outward for a right-handed (t, side, up) frame; check one face.
    v0, v1, v2 = verts[faces[0]]
    if np.dot(np.cross(v1 - v0, v2 - v0), v0 - c[0]) < 0:
        faces = faces[:, ::-1]
    return verts, faces.astype(np.int64)


def rotation_matrix(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """(3, 3) R = Rz(yaw) Ry(pitch) Rx(roll): right-handed rotations about x, y, z."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll_rad), math.sin(roll_rad), math.cos(pitch_rad), math.sin(pitch_rad),
                              math.cos(yaw_rad), math.sin(yaw_rad))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def compass_to_yaw_rad(heading_deg) -> np.ndarray:
    """Compass heading [deg, 0 north, clockwise] -> yaw [rad, 0 east, counter-clockwise]."""
    return np.radians(90.0 - np.asarray(heading_deg, float))


def _ground_z(position, heightfield) -> float:
    if len(position) == 3:
        return float(position[2])
    if heightfield is None:
        raise ParameterError("an object placed by [x, y] needs a seabed to sit on")
    return float(heightfield.height(position[0], position[1]))


def cable_centreline(points_m, diameter_m: float, burial_fraction, heightfield: HeightField | None,
                     step_m: float = 0.05, stiffness_length_m: float = 0.5) -> np.ndarray:
    """(n, 3) centreline [m] of a cable through the (x, y[, z]) points, lying on the seabed.

    A natural cubic spline through the points (chord-length parameter), resampled every ``step_m``. The
    seabed height along it is low-passed over ``stiffness_length_m`` (a stiff cable bridges ripple troughs),
    and the centre sits at z = h + r - burial * 2 r: ``burial`` of the diameter lies below the surface.
    """
    from scipy.interpolate import CubicSpline
    from scipy.ndimage import gaussian_filter1d

    pts = np.asarray(points_m, float)
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1))]
    keep = np.r_[True, np.diff(chord) > 1e-9]
    pts, chord = pts[keep], chord[keep]
    n = max(2, int(math.ceil(chord[-1] / step_m)) + 1)
    s = np.linspace(0.0, chord[-1], n)
    if len(pts) >= 3:
        xy = CubicSpline(chord, pts[:, :2], bc_type="natural")(s)
    else:
        xy = np.c_[np.interp(s, chord, pts[:, 0]), np.interp(s, chord, pts[:, 1])]
    r = 0.5 * diameter_m
    burial = np.interp(s, chord, np.broadcast_to(np.asarray(burial_fraction, float), chord.shape))
    if pts.shape[1] == 3:
        ground = np.interp(s, chord, pts[:, 2])
    else:
        if heightfield is None:
            raise ParameterError("a cable given by [x, y] points needs a seabed to lie on")
        ground = heightfield.height(xy[:, 0], xy[:, 1])
        if stiffness_length_m > 0:
            ground = gaussian_filter1d(ground, stiffness_length_m / (s[1] - s[0]), mode="nearest")
    return np.c_[xy, ground + r - burial * 2.0 * r]


def panel_mesh(center_m, size_m, normal, up):
    """Two triangles: a width x height rectangle centred at ``center_m`` facing ``normal``."""
    n = np.asarray(normal, float)
    n /= np.linalg.norm(n)
    u = np.asarray(up, float)
    u = u - np.dot(u, n) * n
    if np.linalg.norm(u) < 1e-9:
        u = np.array([1.0, 0.0, 0.0]) - n[0] * n
    u /= np.linalg.norm(u)
    w = np.cross(u, n)  # width direction; (w, u, n) right-handed
    hw, hh = 0.5 * size_m[0], 0.5 * size_m[1]
    c = np.asarray(center_m, float)
    verts = np.array([c - hw * w - hh * u, c + hw * w - hh * u, c + hw * w + hh * u, c - hw * w + hh * u])
    return verts, np.array([[0, 1, 2], [0, 2, 3]], np.int64)


# ------------------------------------------------------------------------------------------------------
# Scene from a validated config
# ------------------------------------------------------------------------------------------------------

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

    seabed_meshes = {} if hf is not None else {i: _seabed_object_mesh(config.objects[i], i)
                                                for i in config.seabed_objects}
    if seabed_meshes:
        hf, info = seabed_of_meshes(config.objects, seabed_meshes)
    for index, obj in enumerate(config.objects):
        refl, label = reflectance_of(obj), LABELS[obj.label]
        centreline = None
        if index in seabed_meshes:
            v, f = seabed_meshes[index]
        elif isinstance(obj, CableObject):
            line = cable_centreline(obj.points_m, obj.diameter_m, obj.burial_fraction, hf, obj.step_m,
                                    obj.stiffness_length_m)
            v, f = tube(line, 0.5 * obj.diameter_m, obj.sides)
            centreline = line
        elif isinstance(obj, MooredMineObject):
            ground = _ground_z(obj.position_m, hf)
            x, y = obj.position_m[:2]
            import trimesh  # here only: importing it takes about a second that other scenes need not pay

            sphere = trimesh.creation.icosphere(subdivisions=3, radius=obj.radius_m)
            sv = sphere.vertices + [x, y, ground + obj.height_m]
            tv, tf = frustum(0.5 * obj.tether_diameter_m, 0.5 * obj.tether_diameter_m,
                             obj.height_m - obj.radius_m + 0.05, sections=8)
            tv = tv + [x, y, ground - 0.05]
            v = np.vstack([sv, tv])
            f = np.vstack([sphere.faces, tf + len(sv)])
        elif isinstance(obj, CylinderMineObject):
            ground = _ground_z(obj.position_m, hf)
            v, f = frustum(obj.radius_m, obj.radius_m, obj.length_m, sections=32)
            v = v - [0.0, 0.0, 0.5 * obj.length_m]
            # Axis z -> horizontal along the heading: pitch 90 deg puts it along x, then yaw.
            rot = rotation_matrix(0.0, math.pi / 2, float(compass_to_yaw_rad(obj.heading_deg)))
            z = ground + obj.radius_m - obj.burial_fraction * 2.0 * obj.radius_m
            v = v @ rot.T + [obj.position_m[0], obj.position_m[1], z]
        elif isinstance(obj, ConeMineObject):
            ground = _ground_z(obj.position_m, hf)
            v, f = frustum(obj.bottom_radius_m, obj.top_radius_m, obj.height_m, sections=32)
            v = v + [obj.position_m[0], obj.position_m[1], ground - obj.burial_fraction * obj.height_m]
        elif isinstance(obj, PanelObject):
            v, f = panel_mesh(obj.center_m, obj.size_m, obj.normal, obj.up)
        elif isinstance(obj, MeshObject):
            v, f = placed_mesh(obj, index, hf)
        else:  # pragma: no cover - config only produces the types above
            raise ParameterError(f"object type {type(obj).__name__} is not supported")
        if not (np.abs(v) <= MAX_COORDINATE_M).all():  # NaN included
            raise ConfigError(f"objects[{index}] ({obj.name!r}): its sizes and position give coordinates that are not "
                              f"finite or beyond +-{MAX_COORDINATE_M:.0e} m; check them (metres)")
        kind = "seabed" if index in seabed_meshes else obj.type  # a mesh seabed is the background, as the procedural
        parts.append(Part(obj.name, kind, v, f, label, refl, centreline, one_surface=index in seabed_meshes))
    if site:
        return site_scene(hf, SceneObject(0, "seabed", "seabed", LABELS[sb.label], reflectance_of(sb), 0, 0), parts,
                          tile_m, crs=to_crs(config.crs), seabed_info=info, cell_reflectance=cell_reflectance)
    return Scene(parts, hf, crs=to_crs(config.crs), seabed_info=info)


def _seabed_object_mesh(obj, index: int) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (n, 3) and faces (m, 3) of a surface that is the seabed (:attr:`SceneConfig.seabed_objects`)."""
    if isinstance(obj, PanelObject):
        return panel_mesh(obj.center_m, obj.size_m, obj.normal, obj.up)
    return placed_mesh(obj, index, None)


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


def placed_mesh(obj: MeshObject, index: int, hf: HeightField | None) -> tuple[np.ndarray, np.ndarray]:
    """A ``mesh`` object's vertices (n, 3) and faces (m, 3), scaled, rotated and translated into the world."""
    v, f = load_mesh_file(obj, index)
    rot = rotation_matrix(*np.radians(obj.rotate_deg))
    v = v * obj.scale @ rot.T
    if len(obj.translate_m) == 2:
        if obj.label == "seabed":
            raise ConfigError(f"objects[{index}].translate_m = {list(obj.translate_m)}: a mesh labelled seabed is the "
                              "seabed and cannot rest on one; give [x, y, z]")
        ground = _ground_z(obj.translate_m, hf)
        return v + [obj.translate_m[0], obj.translate_m[1], ground - v[:, 2].min()], f
    return v + np.asarray(obj.translate_m), f


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
        some_area = _nondegenerate(v, f).any()
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


def plate_scene(distance_m: float, size_m: float = 20.0, center_xy_m=(0.0, 0.0), origin_m=(0.0, 0.0, 0.0),
                reflectance: float = 0.1) -> Scene:
    """A square plate facing +z, ``distance_m`` below ``origin_m`` (the overlap check's target)."""
    o = np.asarray(origin_m, float)
    v, f = panel_mesh(o + [center_xy_m[0], center_xy_m[1], -distance_m], (size_m, size_m), (0, 0, 1), (0, 1, 0))
    return Scene([Part("plate", "panel", v, f, LABELS["panel"], reflectance)])
