"""The ``auto`` fidelity level's ray stage: ``balanced``'s hits, with Embree casting only what it must, and each
simple footprint's echoes collapsed to two (:mod:`scanner_sim.rays.collapse`).

Embree casts every pulse's axis. Where the axis lands on the seabed's height field and a test on a coarse grid
(:mod:`scanner_sim.rays.seabed_grid`) proves that nothing else can stand in the sub-rays' way or between their hits
and the receiver, and that the seabed rises along each sub-ray less steeply than the ray does, each other sub-ray meets
the seabed exactly once, on the triangle the height field puts under it: its hit is the ray-plane intersection
(:mod:`scanner_sim.rays.seabed_kernels`) and its shadow ray cannot be blocked. Every other pulse is cast as
``balanced`` casts it.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from scanner_sim.rays.beams import BeamPattern
from scanner_sim.rays.cast import Hits, cast_beams, kernel_inputs
from scanner_sim.rays.collapse import HIT_FIELDS, collapse_simple, emit_rows, pulse_figures
from scanner_sim.rays.kernels import HitRows, ShadowRays, clear_blocked, hit_block, subrays_local32
from scanner_sim.rays.seabed_grid import seabed_grid_of
from scanner_sim.rays.seabed_kernels import analytic_block, unproven_shadows

#: Sub-rays per block of :func:`cast_seabed_analytic`.
AUTO_BLOCK_RAYS = 32768


@numba.njit(cache=True, nogil=True)
def _unproven_rows(prim, tfar, analytic, p0, rays, layout, faces, apex_behind, cos_half_fov, rows, shadows):
    """:func:`scanner_sim.rays.kernels.hit_block` over the block's pulses that ``analytic`` leaves to Embree:
    their hit rows and shadow rays packed from 0, in pulse order. Returns the row count."""
    m = layout.xy.shape[0]
    sh_o, sh_d, sh_len = shadows
    c = 0
    for q in range(analytic.shape[0]):
        if not analytic[q]:
            c += hit_block(prim[q * m:(q + 1) * m], tfar[q * m:(q + 1) * m], (p0 + q) * m, c, rays, layout, faces,
                           apex_behind, cos_half_fov, rows, (sh_o[c:], sh_d[c:], sh_len[c:]))
    return c


@numba.njit(cache=True, nogil=True)
def _block_collapsed(prim, tfar, analytic, p0, rays, layout, faces, apex_behind, cos_half_fov, unproven, out):
    """The block's rows as :func:`collapse_simple` keeps them, pulse by pulse into ``out`` (HIT_FIELDS order, room
    for every sub-ray): a proven pulse's hit rows made (:func:`scanner_sim.rays.kernels.hit_block`) and collapsed
    while in cache, the others' collapsed from ``unproven`` (their rows, shadow rays applied, in HIT_FIELDS order
    with incidence cosines). Returns the rows written."""
    m = layout.xy.shape[0]
    one = HitRows(np.empty(m, np.int64), np.empty(m, np.int32), np.empty(m), np.empty((m, 3)),
                  np.empty((m, 3), np.float32), np.empty(m), np.empty(m), np.empty(m, np.int16),
                  np.empty(m, np.int32), np.empty(m), np.empty(m, np.float32), np.empty(m))
    one_fields = (one.pulse, one.sub, one.range_m, one.point, one.normal, one.cos_inc, one.reflectance, one.label,
                  one.object_id, one.seen, one.weight, one.rx_dist)
    shadows = (np.empty((m, 3), np.float32), np.empty((m, 3), np.float32), np.empty(m, np.float32))
    energy, tau, nodes, share = np.empty(m), np.empty(m), np.empty(2), np.empty(2)
    unproven_pulse = unproven[0]
    o, u = 0, 0
    for q in range(analytic.shape[0]):
        p = p0 + q
        if analytic[q]:
            c = hit_block(prim[q * m:(q + 1) * m], tfar[q * m:(q + 1) * m], p * m, 0, rays, layout, faces,
                          apex_behind, cos_half_fov, one, shadows)
            beam, rho_mean, cosine, mean_range = pulse_figures(0, c, m, one_fields, False, energy, tau, nodes, share)
            o = emit_rows(0, c, one_fields, False, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
        else:
            start = u
            while u < unproven_pulse.shape[0] and unproven_pulse[u] == p:
                u += 1
            if u > start:
                beam, rho_mean, cosine, mean_range = pulse_figures(start, u, m, unproven, False, energy, tau,
                                                                   nodes, share)
                o = emit_rows(start, u, unproven, False, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
    return o


def _scratch_rows(caster, n: int):
    """HitRows of n rows in ``caster``'s per-thread workspace (reused block after block: no fresh pages)."""
    shapes = dict(point=(n, 3), normal=(n, 3))
    return HitRows(*(caster.workspace(f"auto_rows_{name}", shapes.get(name, (n,)), a.dtype)
                     for name, a in zip(HitRows._fields, HitRows.empty(0))))


def _fields_of(rows, c: int) -> tuple:
    """The first c rows of HitRows in :data:`scanner_sim.rays.collapse.HIT_FIELDS` order (incidence as cosines)."""
    return (rows.pulse[:c], rows.sub[:c], rows.range_m[:c], rows.point[:c], rows.normal[:c], rows.cos_inc[:c],
            rows.reflectance[:c], rows.label[:c], rows.object_id[:c], rows.seen[:c], rows.weight[:c],
            rows.rx_dist[:c])


#: The dtype of each field of :data:`scanner_sim.rays.collapse.HIT_FIELDS` (as scanner_sim.rays.cast.cast_beams gives them).
_DTYPES = (np.int64, np.int32, np.float64, np.float64, np.float32, np.float64, np.float64, np.int16, np.int32,
           np.float64, np.float64, np.float32)


def _scratch_out(caster, n: int) -> tuple:
    """Room for n rows in :data:`scanner_sim.rays.collapse.HIT_FIELDS` order, in ``caster``'s per-thread workspace."""
    return tuple(caster.workspace(f"auto_out_{f}", (n, 3) if f in ("point", "normal") else (n,), t)
                 for f, t in zip(HIT_FIELDS, _DTYPES))


def _concatenate(parts: list[Hits], n_pulses: int, m: int) -> Hits:
    """The blocks' hits as one, in their order."""
    if len(parts) == 1:
        return dataclasses.replace(parts[0], n_pulses=n_pulses)
    return Hits(**{f: np.concatenate([getattr(h, f) for h in parts]) for f in HIT_FIELDS}, n_pulses=n_pulses,
                n_subrays=m)


def cast_seabed_analytic(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern,
                         geometry, shadow_rays: bool = True, collapse: bool = False) -> Hits:
    """:func:`scanner_sim.rays.cast.cast_beams`, with Embree casting only what it must: every pulse's axis, and
    the other sub-rays and shadow rays of the pulses :func:`scanner_sim.rays.seabed_kernels.analytic_block` cannot prove.
    A proven pulse's sub-rays meet the seabed triangles the height field puts under them, at the distance the
    ray-plane intersection gives (rounded to float32 as Embree's), and nothing can stand between its hits and the
    receiver. The hit rows are made by the same kernel as ``cast_beams``'s, so they differ from it by float32
    rounding of the distances at most. Same arguments and result; a scene without a height field is cast as
    ``cast_beams`` casts it. ``collapse``: each block's hits go through :func:`collapse_simple` while in cache."""
    grid = seabed_grid_of(caster, scene)
    if grid is None:
        hits = cast_beams(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                          shadow_rays)
        return collapse_simple(hits) if collapse else hits
    n_pulses, m = beam_origin.shape[0], pattern.count
    rays, layout, faces, cone = kernel_inputs(scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern,
                                              geometry)
    block = max(1, AUTO_BLOCK_RAYS // m)
    size = min(n_pulses, block) * m  # every block's scratch, fetched once (a workspace call is ~10 us)
    rows = _scratch_rows(caster, size)
    o32_all = caster.workspace("origins32", (size, 3), np.float32)
    d32_all = caster.workspace("dirs32", (size, 3), np.float32)
    prim_all = caster.workspace("auto_prim", (size,), np.int32)
    tfar_all = caster.workspace("auto_tfar", (size,), np.float32)
    shadows = ShadowRays(caster.workspace("shadow_origins32", (size, 3), np.float32),
                         caster.workspace("shadow_dirs32", (size, 3), np.float32),
                         caster.workspace("shadow_length32", (size,), np.float32))
    out = _scratch_out(caster, size) if collapse else None
    rest_sub = np.arange(1, m)
    parts = []
    for p0 in range(0, n_pulses, block):
        p1 = min(n_pulses, p0 + block)
        b = (p1 - p0) * m
        o32, d32, prim, tfar = o32_all[:b], d32_all[:b], prim_all[:b], tfar_all[:b]
        subrays_local32(rays, p0, p1, layout, o32, d32)
        axis_prim, axis_tfar = caster.first_hits_raw(np.ascontiguousarray(o32[::m]), np.ascontiguousarray(d32[::m]))
        analytic = np.empty(p1 - p0, bool)
        analytic_block(o32, d32, axis_prim, axis_tfar, p0, rays.rx, grid, shadow_rays, prim, tfar, analytic)
        cast = np.flatnonzero(~analytic)
        if cast.size:
            at = (cast[:, None] * m + rest_sub).ravel()
            prim[at], tfar[at] = caster.first_hits_raw(o32[at], d32[at])
        if collapse:
            c = _unproven_rows(prim, tfar, analytic, p0, rays, layout, faces, cone.apex_behind_m, cone.cos_half_fov,
                               rows, shadows)
            if shadow_rays and c:
                occluded = caster.occluded_raw(shadows.origin[:c], shadows.direction[:c], shadows.length[:c])
                clear_blocked(occluded, shadows.length[:c], rows.seen, 0)
            k = _block_collapsed(prim, tfar, analytic, p0, rays, layout, faces, cone.apex_behind_m,
                                 cone.cos_half_fov, _fields_of(rows, c), out)
            parts.append(Hits(**{f: a[:k].copy() for f, a in zip(HIT_FIELDS, out)}, n_pulses=p1 - p0, n_subrays=m))
            continue
        c = hit_block(prim, tfar, p0 * m, 0, rays, layout, faces, cone.apex_behind_m, cone.cos_half_fov, rows,
                      shadows)
        if shadow_rays and c:
            need = unproven_shadows(rows.pulse[:c], p0, analytic, shadows.length[:c])
            if need.size:
                occluded = caster.occluded_raw(shadows.origin[need], shadows.direction[need], shadows.length[need])
                rows.seen[need[occluded >= 0]] = 0.0
        part = Hits(**dict(zip(HIT_FIELDS, (a.copy() for a in _fields_of(rows, c)))), n_pulses=p1 - p0, n_subrays=m)
        np.arccos(part.incidence_rad, out=part.incidence_rad)
        parts.append(part)
    if not parts:
        return cast_beams(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                          shadow_rays)
    return _concatenate(parts, n_pulses, m)


def cast_auto(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern, geometry,
              shadow_rays: bool = True) -> Hits:
    """:func:`scanner_sim.rays.cast.cast_beams` for the ``auto`` level: ``balanced``'s hits, the seabed's found
    analytically where that is proven exact (:func:`cast_seabed_analytic`), each simple pulse's echoes collapsed
    to two (:func:`collapse_simple`, block by block). Same arguments and result; rows in scan order."""
    return cast_seabed_analytic(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern,
                                geometry, shadow_rays, collapse=True)
