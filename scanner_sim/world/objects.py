"""The scene's objects as meshes: the generators (a frustum, a tube, a panel, a cable's centreline on the seabed), and
one builder per object type, which :func:`object_mesh` dispatches to through :data:`OBJECT_BUILDERS` (each gives
vertices (n, 3) float64 world [m] and faces (m, 3) int64, outward normals)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

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
)
from scanner_sim.world.icosphere import icosphere
from scanner_sim.world.mesh_file import load_mesh_file
from scanner_sim.world.terrain import HeightField


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


def seabed_object_mesh(obj, index: int) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (n, 3) and faces (m, 3) of a surface that is the seabed (:attr:`SceneConfig.seabed_objects`)."""
    if isinstance(obj, PanelObject):
        return panel_mesh(obj.center_m, obj.size_m, obj.normal, obj.up)
    return placed_mesh(obj, index, None)


class ObjectMesh(NamedTuple):
    """An object's mesh in the world: vertices (n, 3) float64 [m], faces (m, 3) int64, and the centreline (k, 3) [m]
    of a cable (None for any other object)."""

    vertices: np.ndarray
    faces: np.ndarray
    centreline: np.ndarray | None = None


def _cable(obj: CableObject, index: int, hf: HeightField | None) -> ObjectMesh:
    line = cable_centreline(obj.points_m, obj.diameter_m, obj.burial_fraction, hf, obj.step_m, obj.stiffness_length_m)
    v, f = tube(line, 0.5 * obj.diameter_m, obj.sides)
    return ObjectMesh(v, f, line)


def _moored_mine(obj: MooredMineObject, index: int, hf: HeightField | None) -> ObjectMesh:
    """A sphere on a tether standing on the ground."""
    ground = _ground_z(obj.position_m, hf)
    x, y = obj.position_m[:2]
    sphere_vertices, sphere_faces = icosphere(subdivisions=3, radius_m=obj.radius_m)
    sv = sphere_vertices + [x, y, ground + obj.height_m]
    tv, tf = frustum(0.5 * obj.tether_diameter_m, 0.5 * obj.tether_diameter_m,
                     obj.height_m - obj.radius_m + 0.05, sections=8)
    tv = tv + [x, y, ground - 0.05]
    return ObjectMesh(np.vstack([sv, tv]), np.vstack([sphere_faces, tf + len(sv)]))


def _cylinder_mine(obj: CylinderMineObject, index: int, hf: HeightField | None) -> ObjectMesh:
    """A cylinder lying along its heading, buried by its ``burial_fraction`` of its diameter."""
    ground = _ground_z(obj.position_m, hf)
    v, f = frustum(obj.radius_m, obj.radius_m, obj.length_m, sections=32)
    v = v - [0.0, 0.0, 0.5 * obj.length_m]
    # Axis z -> horizontal along the heading: pitch 90 deg puts it along x, then yaw.
    rot = rotation_matrix(0.0, math.pi / 2, float(compass_to_yaw_rad(obj.heading_deg)))
    z = ground + obj.radius_m - obj.burial_fraction * 2.0 * obj.radius_m
    return ObjectMesh(v @ rot.T + [obj.position_m[0], obj.position_m[1], z], f)


def _cone_mine(obj: ConeMineObject, index: int, hf: HeightField | None) -> ObjectMesh:
    """A truncated cone standing on the ground, buried by its ``burial_fraction`` of its height."""
    ground = _ground_z(obj.position_m, hf)
    v, f = frustum(obj.bottom_radius_m, obj.top_radius_m, obj.height_m, sections=32)
    return ObjectMesh(v + [obj.position_m[0], obj.position_m[1], ground - obj.burial_fraction * obj.height_m], f)


def _panel(obj: PanelObject, index: int, hf: HeightField | None) -> ObjectMesh:
    return ObjectMesh(*panel_mesh(obj.center_m, obj.size_m, obj.normal, obj.up))


def _mesh(obj: MeshObject, index: int, hf: HeightField | None) -> ObjectMesh:
    return ObjectMesh(*placed_mesh(obj, index, hf))


#: Object type (a config class) -> its builder: (the object, its index in ``objects``, the seabed's height field or
#: None) -> :class:`ObjectMesh`.
OBJECT_BUILDERS: dict[type, Callable[..., ObjectMesh]] = {
    CableObject: _cable, MooredMineObject: _moored_mine, CylinderMineObject: _cylinder_mine,
    ConeMineObject: _cone_mine, PanelObject: _panel, MeshObject: _mesh,
}


def object_mesh(obj, index: int, hf: HeightField | None) -> ObjectMesh:
    """The mesh of ``objects[index]`` (``obj``) in the world, on the seabed ``hf`` (None: no seabed) where the
    object is placed by [x, y]."""
    builder = OBJECT_BUILDERS.get(type(obj))
    if builder is None:  # pragma: no cover - config only produces the types above
        raise ParameterError(f"object type {type(obj).__name__} is not supported")
    return builder(obj, index, hf)
