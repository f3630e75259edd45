"""The geometry stage of a pass: beam sub-rays of a chunk of pulses -> first hits -> per-hit range, point,
normal, incidence, material -> receiver check (the share of the aperture whose field holds the hit, then a
shadow ray from the hit to the aperture) -> :class:`~scanner_sim.rays.hits.Hits`, struct-of-arrays in scan order
with back-references.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from scanner_sim.rays import kernels
from scanner_sim.rays.beams import BeamPattern, perpendicular_basis
from scanner_sim.rays.caster import RayCaster
from scanner_sim.rays.hits import Hits, empty_columns, head
from scanner_sim.rays.seabed_grid import seabed_grid
from scanner_sim.rays.seabed_kernels import shadows_to_cast

#: Rays per block inside :func:`cast_beams` (measured: 16k-64k keep a block's working set in cache).
BLOCK_RAYS = 32768


@dataclass(frozen=True)
class CastScene:
    """The scene as the ray stage casts into it, built once per scene object (:meth:`of`): the
    :class:`~scanner_sim.world.scene.Scene`, its mesh in the local frame behind a
    :class:`~scanner_sim.rays.caster.RayCaster` (BVH built), and the seabed's proof grid
    (:func:`~scanner_sim.rays.seabed_grid.seabed_grid`; None without a height field)."""

    scene: object
    caster: RayCaster
    seabed_grid: object | None

    @classmethod
    def build(cls, scene, backend: str = "auto") -> CastScene:
        """Build the BVH and the proof grid of ``scene`` afresh."""
        caster = RayCaster.for_scene(scene, backend)
        return cls(scene, caster, seabed_grid(scene, caster))

    @classmethod
    def of(cls, scene, backend: str = "auto") -> CastScene:
        """:meth:`build` once for each scene object alive in this process: the passes of one scene (a campaign's, a
        study's, the bench's; :func:`~scanner_sim.survey.setup_cache.cached_scene` hands them one object) share its
        BVH and proof grid, which are dropped with the scene object."""
        key = (id(scene), backend)
        built = _BUILT.get(key)
        if built is not None:
            return cls(scene, *built)
        target = cls.build(scene, backend)
        _BUILT[key] = (target.caster, target.seabed_grid)
        weakref.finalize(scene, _BUILT.pop, key, None)
        return target


#: The caster and proof grid of each scene object alive in this process, by (id, backend) (:meth:`CastScene.of`); a
#: scene's own entry is removed when the scene is (so an id is never met again for another scene). cable_survey's
#: 352,488 triangles take 0.3 s of set-up a pass to build them.
_BUILT: dict[tuple[int, str], tuple[RayCaster, object]] = {}


def shadow_offset_m(local_extent_m: float) -> float:
    """Scale-aware step [m] off a surface for a shadow ray: well above the float32 spacing of the local frame.

    Follows trimesh's idea (ray_pyembree: offset proportional to the mesh scale, with a floor): 1e-6 of the
    scene's local extent, at least 1e-5 m (float32 at 100 m from the local origin resolves 8e-6 m).
    """
    return max(1e-5, 1e-6 * float(local_extent_m))


def cast_beams(target: CastScene, beam_origin: np.ndarray, beam_dir: np.ndarray, shaft_dir: np.ndarray,
               rx_origin: np.ndarray, rx_dir: np.ndarray, pattern: BeamPattern, geometry,
               shadow_rays: bool = True, prove_shadows: bool = True) -> Hits:
    """Cast the sub-rays of a chunk of pulses into ``scene`` and check each hit against the receiver.

    beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir: (n_pulses, 3) float64 world frame (from
    :meth:`scanner_sim.motion.scanner.Scanner.world_rays`); pattern: sub-ray layout; geometry: the instrument's
    :class:`muls.instrument.overlap.TransceiverGeometry` (beam radius, divergence, receiver aperture and FOV);
    shadow_rays: cast a visibility ray from each hit the receiver sees to its aperture (else only its field);
    prove_shadows: over a seabed height field, leave out the shadow rays of each pulse whose hits all lie on the
    seabed with nothing that can stand between them and the aperture (proven on the seabed's coarse grid,
    :func:`scanner_sim.rays.seabed_kernels.shadows_to_cast`): Embree would find none of them blocked, so the hits are
    the same either way. ``target``: the scene and its caster. Returns :class:`Hits` in scan order.

    The work around the two Embree calls is two fused numba kernels (sub-rays in; hit attributes, FOV cone
    and shadow rays out), so the stage keeps most of Embree's raw throughput (``scanner-sim bench-rays``).
    """
    n_pulses, m = beam_origin.shape[0], pattern.count
    scene, caster = target.scene, target.caster
    rays, layout, faces, view = kernel_inputs(scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern,
                                              geometry)
    rows = empty_columns(n_pulses * m)  # sized for every sub-ray hitting; only rows written are kept
    grid = target.seabed_grid if shadow_rays and prove_shadows else None

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
        c = kernels.hit_block(prim, tfar, p0 * m, base, rays, layout, faces, view, rows, shadows)
        if shadow_rays and c and grid is None:  # hits the receiver cannot see have empty (length -1) shadow rays
            occluded = caster.occluded_raw(shadows.origin[:c], shadows.direction[:c], shadows.length[:c])
            kernels.clear_blocked(occluded, shadows.length[:c], rows.receiver_weight, base)
        elif shadow_rays and c:
            need = caster.workspace("shadows_to_cast", (c,), np.int64)
            segments = caster.workspace("shadow_segments", (7, m), np.float64)
            rows_of = caster.workspace("shadow_rows", (m,), np.int64)
            need = need[:shadows_to_cast(grid, rows, scene.local_origin, rays.rx, shadows.length[:c], base, c, need,
                                         segments, rows_of)]
            if need.size:
                occluded = caster.occluded_raw(shadows.origin[need], shadows.direction[need], shadows.length[need])
                rows.receiver_weight[base + need[occluded >= 0]] = 0.0
        base += c

    rows = head(rows, base)
    np.arccos(rows.incidence_rad, out=rows.incidence_rad)  # the kernel wrote cos(incidence)
    return Hits.from_columns(rows, n_pulses, m)


def kernel_inputs(scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern, geometry):
    """What the ray-stage kernels take, from :func:`cast_beams`' arguments: the pulses' rays in the local frame,
    the sub-ray layout, the scene's faces and how the receiver sees a hit (scanner_sim.rays.kernels' named tuples)."""
    beam_dir = np.ascontiguousarray(beam_dir, dtype=np.float64)
    u, v = perpendicular_basis(beam_dir, np.asarray(shaft_dir, float))
    rays = kernels.PulseRays(np.ascontiguousarray(beam_origin - scene.local_origin), beam_dir, u, v,
                             np.ascontiguousarray(rx_origin - scene.local_origin),
                             np.ascontiguousarray(rx_dir, dtype=np.float64))
    layout = kernels.SubrayLayout(np.ascontiguousarray(pattern.xy), pattern.weight, 0.5 * geometry.beam_diameter_m,
                                  math.tan(0.5 * geometry.beam_divergence_full_rad))
    faces = kernels.SceneFaces(scene.face_normal, scene.face_reflectance, scene.face_label, scene.face_object,
                               scene.face_surface, scene.local_origin, shadow_offset_m(scene.local_extent_m))
    return rays, layout, faces, kernels.ReceiverView.of(geometry)



@dataclass(frozen=True)
class BeamCast:
    """A level's ray stage bound to its pass once (the scene, the sub-ray pattern, the instrument's geometry,
    whether shadow rays are cast): ``stage(beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir) -> Hits``, the
    arguments as :meth:`scanner_sim.motion.scanner.Scanner.world_rays` gives them (:func:`cast_beams`)."""

    target: CastScene
    pattern: BeamPattern
    geometry: object
    shadow_rays: bool

    def __call__(self, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir) -> Hits:
        return cast_beams(self.target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, self.pattern,
                          self.geometry, self.shadow_rays)
