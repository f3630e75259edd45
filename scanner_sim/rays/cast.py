"""Ray casting of beam sub-rays and the receiver check, behind one small backend interface.

:class:`RayCaster` is the backend: first hits and occlusion queries of float32 rays in the scene's local
frame. ``embree`` (embreex, Embree 4) is the fast one; ``numpy`` (trimesh's pure-python triangle test) is a
slow fallback for machines without embreex. ``auto`` picks embree when it imports and otherwise warns once
and falls back; asking for ``embree`` explicitly when embreex is missing raises at once.

:func:`cast_beams` is the geometry stage of the pipeline: beam sub-rays of a chunk of pulses -> first hits
-> per-hit range, point, normal, incidence, material -> receiver check (FOV cone, then a shadow ray from the
hit to the receiver aperture) -> :class:`Hits`, struct-of-arrays in scan order with back-references.
"""

from __future__ import annotations

import math
import threading
import warnings
from dataclasses import dataclass

import numpy as np

from muls.errors import ParameterError
from scanner_sim.rays.beams import BeamPattern, perpendicular_basis
from scanner_sim.rays.seabed_grid import seabed_grid_of
from scanner_sim.rays.seabed_kernels import shadows_to_cast

BACKENDS = ("auto", "embree", "numpy")


_MEMORY_TUNED = False


def tune_memory(mmap_threshold_bytes: int = 64 << 20, trim_threshold_bytes: int = 512 << 20) -> bool:
    """Keep glibc from returning chunk-sized arrays to the OS after every chunk (process-wide, idempotent).

    Measured with a profiler on this 2-core VM (scanner-sim bench-rays, 20,000 pulses x 19 sub-rays): the
    geometry stage's fresh multi-megabyte arrays (Hits, Embree's outputs) were each mmapped and page-faulted
    anew per chunk, which cost as much as 25 ms of 175 ms; with these thresholds the memory is reused and
    the hit kernel halves. Call once at program start (``scanner-sim`` does); returns False where mallopt is
    unavailable (not glibc), which only costs speed.
    """
    global _MEMORY_TUNED
    if _MEMORY_TUNED:
        return True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3  # from glibc's malloc.h
        ok = bool(libc.mallopt(m_mmap_threshold, int(mmap_threshold_bytes))) and bool(
            libc.mallopt(m_trim_threshold, int(trim_threshold_bytes)))
    except (OSError, AttributeError):
        return False
    _MEMORY_TUNED = ok
    return ok


def embree_available() -> bool:
    try:
        import embreex.rtcore_scene  # noqa: F401
    except Exception:  # pragma: no cover - depends on the machine
        return False
    return True


class RayCaster:
    """First-hit and occlusion queries against one triangle mesh in a local frame.

    vertices_local: (n_vertices, 3) float, metres, already shifted near the origin (the scene does this);
    faces: (n_faces, 3) int. Rays passed in are float32 in the same local frame (converted if needed).
    """

    def __init__(self, vertices_local: np.ndarray, faces: np.ndarray, backend: str = "auto"):
        if backend not in BACKENDS:
            raise ParameterError(f"raycast backend = {backend!r}: must be one of {', '.join(map(repr, BACKENDS))}")
        if backend == "auto":
            backend = "embree" if embree_available() else "numpy"
            if backend == "numpy":
                warnings.warn("embreex is not importable: ray casting falls back to trimesh's numpy "
                              "intersector, about 100 times slower", RuntimeWarning, stacklevel=2)
        self.backend = backend
        self._local = threading.local()
        self.vertices = np.ascontiguousarray(vertices_local, dtype=np.float32)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        if backend == "embree":
            try:
                from embreex import rtcore_scene
                from embreex.mesh_construction import TriangleMesh
            except Exception as exc:
                raise ImportError("raycast backend 'embree' was asked for but embreex does not import "
                                  f"({exc}); install it with `pip install embreex` or use backend 'auto'") from exc
            self._scene = rtcore_scene.EmbreeScene()
            TriangleMesh(scene=self._scene, vertices=self.vertices, indices=self.faces)
            # embreex builds the BVH (commits the scene) on the first query, unguarded: build it now, in one
            # thread, before chunks running side by side can each start a build of the same scene.
            self._scene.run(np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))
        else:
            import trimesh
            from trimesh.ray.ray_triangle import RayMeshIntersector

            self._mesh = trimesh.Trimesh(self.vertices.astype(np.float64), self.faces, process=False)
            self._numpy = RayMeshIntersector(self._mesh)

    @classmethod
    def for_scene(cls, scene, backend: str = "auto") -> RayCaster:
        """The caster over a :class:`scanner_sim.world.scene.Scene`'s mesh in its local frame (builds the BVH)."""
        return cls(scene.vertices - scene.local_origin, scene.faces, backend=backend)

    def workspace(self, name: str, shape: tuple, dtype) -> np.ndarray:
        """A reusable scratch array (per thread) for temporaries that never leave the ray stage.

        Fresh multi-megabyte arrays per chunk cost page faults comparable to the ray casting itself here;
        the stage's float32 ray buffers are reused instead (grown when a chunk is larger).
        """
        pool = self._local.__dict__.setdefault("pool", {})
        size = int(np.prod(shape))
        buf = pool.get(name)
        if buf is None or buf.size < size or buf.dtype != np.dtype(dtype):
            buf = np.empty(max(size, 1), dtype)
            pool[name] = buf
        return buf[:size].reshape(shape)

    # -- the whole interface -------------------------------------------------------------------------------
    def first_hits(self, origins: np.ndarray, directions: np.ndarray):
        """First hit of each ray.

        origins, directions: (n, 3) float32 local frame, directions unit. Returns ``(ray_index (k,) int64,
        tri_index (k,) int64, distance_m (k,) float32)`` for the k rays that hit, in ray (scan) order;
        distance is along the unit direction.
        """
        origins = np.ascontiguousarray(origins, dtype=np.float32)
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        if origins.shape[0] == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32)
        if self.backend == "embree":
            result = self._scene.run(origins, directions, output=1)
            prim = result["primID"]
            ray_index = np.flatnonzero(prim >= 0)
            return ray_index, prim[ray_index].astype(np.int64), result["tfar"][ray_index]
        tri, ray, loc = self._numpy.intersects_id(origins.astype(np.float64), directions.astype(np.float64),
                                                  multiple_hits=False, return_locations=True)
        order = np.argsort(ray, kind="stable")
        ray, tri, loc = ray[order], tri[order], loc[order]
        dist = np.einsum("ij,ij->i", loc - origins[ray], directions[ray])
        return ray.astype(np.int64), tri.astype(np.int64), dist.astype(np.float32)

    def first_hits_raw(self, origins: np.ndarray, directions: np.ndarray):
        """Per-ray answer, no compaction: ``(tri_index (n,) int32, -1 for a miss; distance_m (n,) float32)``."""
        if self.backend == "embree":
            result = self._scene.run(origins, directions, output=1)
            return result["primID"], result["tfar"]
        ray, tri, dist = self.first_hits(origins, directions)
        prim = np.full(origins.shape[0], -1, np.int32)
        tfar = np.full(origins.shape[0], np.inf, np.float32)
        prim[ray], tfar[ray] = tri, dist
        return prim, tfar

    def occluded_raw(self, origins, directions, max_distance_m) -> np.ndarray:
        """Per-ray occlusion answer as Embree gives it: (n,) int, >= 0 when something lies on the ray."""
        if self.backend == "embree":
            return self._scene.run(origins, directions, dists=max_distance_m, query="OCCLUDED")
        return np.where(self.occluded(origins, directions, max_distance_m), 0, -1)

    def occluded(self, origins: np.ndarray, directions: np.ndarray, max_distance_m: np.ndarray) -> np.ndarray:
        """(n,) bool: does any triangle lie on each ray between 0 and ``max_distance_m`` (n,)?

        Rays with ``max_distance_m`` <= 0 are empty: never occluded (Embree skips them).
        """
        origins = np.ascontiguousarray(origins, dtype=np.float32)
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        max_distance_m = np.ascontiguousarray(max_distance_m, dtype=np.float32)
        if origins.shape[0] == 0:
            return np.zeros(0, bool)
        if self.backend == "embree":
            hit = self._scene.run(origins, directions, dists=max_distance_m, query="OCCLUDED") >= 0
            return hit & (max_distance_m > 0.0)
        ray, _, dist = self.first_hits(origins, directions)
        out = np.zeros(origins.shape[0], bool)
        out[ray] = dist < max_distance_m[ray]
        return out & (max_distance_m > 0.0)


@dataclass(frozen=True)
class Hits:
    """First hits of beam sub-rays, one row per sub-ray that hit, in scan order (pulse-major).

    pulse_index (n,) int64: row of the pulse in the chunk; subray_index (n,) int32: sub-ray in the pattern;
    range_m (n,) float64: distance along the sub-ray from its origin; point (n, 3) float64: world position;
    normal (n, 3) float32: unit surface normal facing the incoming ray; incidence_rad (n,) float64: angle
    between the ray and the normal, in [0, pi/2]; reflectance (n,) float64 at 532 nm; label (n,) int16: class
    code (scene.LABELS); object_id (n,) int32: index into Scene.objects; receiver_weight (n,) float64: 1 if the
    hit is inside the receiver FOV cone and seen from the aperture, else 0; weight (n,) float64: the sub-ray's
    share of the pulse energy (weights of one pulse's sub-rays sum to 1); rx_distance_m (n,) float32:
    distance from the hit to the receiver aperture centre (the return leg).
    Sub-rays that miss have no row: a pulse with no row at all is a ``no_hit``.
    """

    pulse_index: np.ndarray
    subray_index: np.ndarray
    range_m: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    incidence_rad: np.ndarray
    reflectance: np.ndarray
    label: np.ndarray
    object_id: np.ndarray
    receiver_weight: np.ndarray
    weight: np.ndarray
    rx_distance_m: np.ndarray
    n_pulses: int
    n_subrays: int

    def __len__(self) -> int:
        return int(self.range_m.shape[0])

    def seen_fraction(self) -> np.ndarray:
        """(n_pulses,) share of each pulse's energy that hit something the receiver sees (ray-cast overlap)."""
        return np.bincount(self.pulse_index, weights=self.weight * self.receiver_weight, minlength=self.n_pulses)

    def hit_fraction(self) -> np.ndarray:
        """(n_pulses,) share of each pulse's energy that hit anything."""
        return np.bincount(self.pulse_index, weights=self.weight, minlength=self.n_pulses)


@dataclass(frozen=True)
class ReceiverCone:
    """The receiver's field of view as a cone with a virtual apex behind the aperture.

    The apex sits ``apex_behind_m`` = (d_r / 2) / tan(fov / 2) behind the aperture centre on the receiver
    axis, so the cone's cross-section at range z in front of the aperture has radius d_r / 2 + z tan(fov / 2),
    the receiver footprint r2 of MULS Eq. 11: on a flat plate the ray-cast overlap converges to Eq. 11.
    """

    apex_behind_m: float
    cos_half_fov: float

    @classmethod
    def from_geometry(cls, geometry) -> ReceiverCone:
        """From a :class:`muls.overlap.TransceiverGeometry`."""
        half = 0.5 * geometry.fov_full_rad
        return cls(apex_behind_m=0.5 * geometry.receiver_diameter_m / math.tan(half), cos_half_fov=math.cos(half))

    def contains(self, points: np.ndarray, rx_origin: np.ndarray, rx_dir: np.ndarray) -> np.ndarray:
        """(n,) bool: is each point (n, 3) inside the cone of the receiver at rx_origin (n, 3), axis rx_dir?"""
        v = points - (rx_origin - self.apex_behind_m * rx_dir)
        along = np.einsum("ij,ij->i", v, rx_dir)
        return along >= self.cos_half_fov * np.sqrt(np.einsum("ij,ij->i", v, v))


def shadow_offset_m(local_extent_m: float) -> float:
    """Scale-aware step [m] off a surface for a shadow ray: well above the float32 spacing of the local frame.

    Follows trimesh's idea (ray_pyembree: offset proportional to the mesh scale, with a floor): 1e-6 of the
    scene's local extent, at least 1e-5 m (float32 at 100 m from the local origin resolves 8e-6 m).
    """
    return max(1e-5, 1e-6 * float(local_extent_m))


def cast_beams(caster: RayCaster, scene, beam_origin: np.ndarray, beam_dir: np.ndarray, shaft_dir: np.ndarray,
               rx_origin: np.ndarray, rx_dir: np.ndarray, pattern: BeamPattern, geometry,
               shadow_rays: bool = True, prove_shadows: bool = True) -> Hits:
    """Cast the sub-rays of a chunk of pulses into ``scene`` and check each hit against the receiver.

    beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir: (n_pulses, 3) float64 world frame (from
    :meth:`scanner_sim.motion.scanner.Scanner.world_rays`); pattern: sub-ray layout; geometry: the instrument's
    :class:`muls.overlap.TransceiverGeometry` (beam radius, divergence, receiver aperture and FOV);
    shadow_rays: cast a visibility ray from each in-cone hit to the receiver aperture (else only the cone);
    prove_shadows: over a seabed height field, leave out the shadow rays of each pulse whose hits all lie on the
    seabed with nothing that can stand between them and the aperture (proven on the seabed's coarse grid,
    :func:`scanner_sim.rays.seabed_kernels.shadows_to_cast`): Embree would find none of them blocked, so the hits are
    the same either way. ``caster``: the :class:`RayCaster` over ``scene`` (:meth:`RayCaster.for_scene`). Returns
    :class:`Hits` in scan order.

    The work around the two Embree calls is two fused numba kernels (sub-rays in; hit attributes, FOV cone
    and shadow rays out), so the stage keeps most of Embree's raw throughput (``scanner-sim bench-rays``).
    """
    n_pulses, m = beam_origin.shape[0], pattern.count
    kernels = _kernels()
    rays, layout, faces, cone = kernel_inputs(scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern,
                                              geometry)
    rows = kernels.HitRows.empty(n_pulses * m)  # sized for every sub-ray hitting; only rows written are kept
    grid = seabed_grid_of(caster, scene) if shadow_rays and prove_shadows else None

    # Blocks of pulses small enough that each block's rays, Embree answers and shadow rays stay in cache.
    block = max(1, BLOCK_RAYS // m)
    base = 0
    for p0 in range(0, n_pulses, block):  # a handful of blocks per chunk, not a loop per pulse
        p1 = min(n_pulses, p0 + block)
        b = (p1 - p0) * m
        o32 = caster.workspace("origins32", (b, 3), np.float32)
        d32 = caster.workspace("dirs32", (b, 3), np.float32)
        kernels.subrays_local32(rays, p0, p1, layout, o32, d32)
        prim, tfar = caster.first_hits_raw(o32, d32)
        shadows = kernels.ShadowRays(caster.workspace("shadow_origins32", (b, 3), np.float32),
                                     caster.workspace("shadow_dirs32", (b, 3), np.float32),
                                     caster.workspace("shadow_length32", (b,), np.float32))
        c = kernels.hit_block(prim, tfar, p0 * m, base, rays, layout, faces, cone.apex_behind_m, cone.cos_half_fov,
                              rows, shadows)
        if shadow_rays and c and grid is None:  # hits outside the cone have empty (length -1) shadow rays
            occluded = caster.occluded_raw(shadows.origin[:c], shadows.direction[:c], shadows.length[:c])
            kernels.clear_blocked(occluded, shadows.length[:c], rows.seen, base)
        elif shadow_rays and c:
            need = caster.workspace("shadows_to_cast", (c,), np.int64)
            need = need[:shadows_to_cast(grid, rows, scene.local_origin, rays.rx, shadows.length[:c], base, c, m, need)]
            if need.size:
                occluded = caster.occluded_raw(shadows.origin[need], shadows.direction[need], shadows.length[need])
                rows.seen[base + need[occluded >= 0]] = 0.0
        base += c

    k = base
    incidence = rows.cos_inc[:k]
    np.arccos(incidence, out=incidence)  # the kernel wrote cos(incidence)
    return Hits(pulse_index=rows.pulse[:k], subray_index=rows.sub[:k], range_m=rows.range_m[:k],
                point=rows.point[:k], normal=rows.normal[:k], incidence_rad=incidence,
                reflectance=rows.reflectance[:k], label=rows.label[:k], object_id=rows.object_id[:k],
                receiver_weight=rows.seen[:k], weight=rows.weight[:k], rx_distance_m=rows.rx_dist[:k],
                n_pulses=n_pulses, n_subrays=m)


def kernel_inputs(scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern, geometry):
    """What the ray-stage kernels take, from :func:`cast_beams`' arguments: the pulses' rays in the local frame,
    the sub-ray layout, the scene's faces and the receiver cone (scanner_sim.rays.kernels' named tuples)."""
    kernels = _kernels()
    beam_dir = np.ascontiguousarray(beam_dir, dtype=np.float64)
    u, v = perpendicular_basis(beam_dir, np.asarray(shaft_dir, float))
    rays = kernels.PulseRays(np.ascontiguousarray(beam_origin - scene.local_origin), beam_dir, u, v,
                             np.ascontiguousarray(rx_origin - scene.local_origin),
                             np.ascontiguousarray(rx_dir, dtype=np.float64))
    layout = kernels.SubrayLayout(np.ascontiguousarray(pattern.xy), pattern.weight, 0.5 * geometry.beam_diameter_m,
                                  math.tan(0.5 * geometry.beam_divergence_full_rad))
    faces = kernels.SceneFaces(scene.face_normal, scene.face_reflectance, scene.face_label, scene.face_object,
                               scene.local_origin, shadow_offset_m(scene.local_extent_m))
    return rays, layout, faces, ReceiverCone.from_geometry(geometry)


#: Rays per block inside :func:`cast_beams` (measured: 16k-64k keep a block's working set in cache).
BLOCK_RAYS = 32768

_KERNELS = None


def _kernels():
    """Compile (once, cached on disk) the numba kernels of :func:`cast_beams`."""
    global _KERNELS
    if _KERNELS is None:
        from scanner_sim.rays import kernels as _raykernels

        _KERNELS = _raykernels
    return _KERNELS
