"""The ``auto`` fidelity level's ray stage: ``balanced``'s hits, with Embree casting only what it must, and each
simple footprint's echoes collapsed to two (:mod:`scanner_sim.rays.collapse`).

Embree casts every pulse's axis. Where the axis lands on the seabed's height field and a test on a coarse grid
(:mod:`scanner_sim.rays.seabed_grid`) proves that nothing else can stand in the sub-rays' way or between their hits
and the receiver, and that the seabed rises along each sub-ray less steeply than the ray does, each other sub-ray meets
the seabed exactly once, on the triangle the height field puts under it: its hit is the ray-plane intersection
(:mod:`scanner_sim.rays.seabed_kernels`) and its shadow ray cannot be blocked. Where the axis meets nothing and the
grid proves that nothing stands anywhere below the bundle, no other sub-ray is cast: none would meet anything. Every
other pulse is cast as ``balanced`` casts it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from muls.infra.borrowed import borrowed
from muls.infra.runtime import kernel
from scanner_sim.rays.cast import BeamCast, CastScene, cast_beams, kernel_inputs
from scanner_sim.rays.collapse import cast_pulse_figures, collapse_simple, emit_rows, pulse_figures, simple_pulses
from scanner_sim.rays.hits import Hits, empty_columns, head
from scanner_sim.rays.kernels import ShadowRays, hit_block, subrays_local32
from scanner_sim.rays.seabed_grid import no_grid_reason
from scanner_sim.rays.seabed_kernels import analytic_block, unproven_shadows

#: Sub-rays per block of :func:`cast_seabed_analytic`.
AUTO_BLOCK_RAYS = 32768


@kernel(nogil=True)
def _left_to_embree(o32, d32, analytic, m, origins, dirs):
    """The sub-rays but the axis of each pulse of the block that ``analytic`` does not prove, packed in scan order
    into ``origins`` and ``dirs`` ((k, 3) float32, room for every ray); returns k."""
    c = 0
    for q in range(analytic.shape[0]):
        if not analytic[q]:
            for k in range(q * m + 1, (q + 1) * m):
                for a in range(3):
                    origins[c, a], dirs[c, a] = o32[k, a], d32[k, a]
                c += 1
    return c


@kernel(nogil=True)
def _embree_answers(prim, tfar, analytic, m, cast_prim, cast_tfar):
    """Embree's answers ``cast_prim``, ``cast_tfar`` for the rays :func:`_left_to_embree` packed, put back in place in
    the block's ``prim`` and ``tfar``."""
    c = 0
    for q in range(analytic.shape[0]):
        if not analytic[q]:
            for k in range(q * m + 1, (q + 1) * m):
                prim[k], tfar[k] = cast_prim[c], cast_tfar[c]
                c += 1


@kernel(nogil=True)
def _proven_figures(prim, tfar, analytic, p0, rays, layout, faces, view, figures, nodes, share, kept, pulse_scratch):
    """For each pulse of the block that ``analytic`` proves, its collapse figures (:func:`cast_pulse_figures`:
    ``figures[q]`` = (beam, rho_mean, cosine, mean_range), ``nodes[q]``, ``share[q]``), summed from its cast without
    making its rows. ``kept`` ((n m,) int32): ``prim`` where a hit row is still to be made (every sub-ray of a pulse
    left to Embree or not simple, the axis alone of a simple one), -1 elsewhere. ``pulse_scratch``: a pulse's
    energies and delays (m,) each, nodes and shares (2,) each. Its arguments borrowed (:mod:`muls.infra.borrowed`)."""
    prim, tfar, analytic, rays, layout, faces, view, figures, nodes, share, kept, pulse_scratch = borrowed(
        (prim, tfar, analytic, rays, layout, faces, view, figures, nodes, share, kept, pulse_scratch))
    m = layout.xy.shape[0]
    energy, tau = pulse_scratch[0], pulse_scratch[1]
    for q in range(analytic.shape[0]):
        first = q * m
        for k in range(first, first + m):  # (a loop: an array assignment compiles numba's shape-error formatting)
            kept[k] = prim[k]
        if analytic[q] and prim[first] >= 0:  # (a proven pulse whose axis met nothing met nothing at all)
            beam, rho_mean, cosine, mean_range = cast_pulse_figures(prim[first:first + m], tfar[first:first + m],
                                                                    p0 + q, rays, layout, faces, view, energy, tau,
                                                                    nodes[q], share[q])
            figures[q, 0], figures[q, 1], figures[q, 2], figures[q, 3] = beam, rho_mean, cosine, mean_range
            if beam >= 0.0:
                kept[first + 1:first + m] = -1


@kernel(nogil=True)
def _collapsed_rows(rows, analytic, p0, m, figures, nodes, share, out, pulse_scratch):
    """The block's hit ``rows`` (scan order, incidence as cosines) as :func:`collapse_simple` keeps them, into
    ``out``: a proven pulse's with the figures :func:`_proven_figures` found, another's with its own
    (:func:`pulse_figures`, in ``pulse_scratch`` as :func:`_proven_figures`'s). Returns the rows written. Its
    arguments borrowed."""
    rows, analytic, figures, nodes, share, out, pulse_scratch = borrowed(
        (rows, analytic, figures, nodes, share, out, pulse_scratch))
    pulse = rows.pulse_index
    energy, tau, own_nodes, own_share = pulse_scratch
    start, o = 0, 0
    while start < pulse.shape[0]:
        stop = start + 1
        while stop < pulse.shape[0] and pulse[stop] == pulse[start]:
            stop += 1
        q = pulse[start] - p0
        if analytic[q]:
            o = emit_rows(start, stop, rows, False, out, o, figures[q, 0], figures[q, 1], figures[q, 2],
                          figures[q, 3], nodes[q], share[q])
        else:
            beam, rho_mean, cosine, mean_range = pulse_figures(start, stop, m, rows, False, energy, tau, own_nodes,
                                                               own_share)
            o = emit_rows(start, stop, rows, False, out, o, beam, rho_mean, cosine, mean_range, own_nodes, own_share)
        start = stop
    return o


def _scratch(caster, prefix: str, n: int):
    """:class:`~scanner_sim.rays.hits.HitColumns` of n rows in ``caster``'s per-thread workspace (reused block
    after block: no fresh pages)."""
    return empty_columns(n, lambda name, shape, dtype: caster.workspace(f"{prefix}_{name}", shape, dtype))


def _cast_unproven_shadows(caster, rows, shadows, c, p0, analytic) -> None:
    """The shadow rays of the block's first ``c`` hit ``rows`` that the proof grid did not prove clear, cast by Embree;
    a blocked one's receiver weight set to 0."""
    if not c:
        return
    need = unproven_shadows(rows.pulse_index[:c], p0, analytic, shadows.length[:c])
    if need.size:
        occluded = caster.occluded_raw(shadows.origin[need], shadows.direction[need], shadows.length[need])
        rows.receiver_weight[need[occluded >= 0]] = 0.0


def _collapse_block(caster, prim, tfar, analytic, p0, rays, layout, faces, view, shadow_rays, rows, shadows, out,
                    scratch) -> int:
    """One block's hit rows, collapsed, into ``out`` (rows made and shadow rays cast only where needed: a proven
    simple pulse's figures come from its cast, and only its axis row is made; a proven pulse's shadow rays are
    clear). Returns the rows written."""
    n, m = analytic.shape[0], layout.xy.shape[0]
    figures, nodes, share = (a[:n] for a in scratch[:3])
    kept, pulse_scratch = scratch[3][:n * m], scratch[4]
    _proven_figures(prim, tfar, analytic, p0, rays, layout, faces, view, figures, nodes, share, kept, pulse_scratch)
    c = hit_block(kept, tfar, p0 * m, 0, rays, layout, faces, view, rows, shadows)
    if shadow_rays:
        _cast_unproven_shadows(caster, rows, shadows, c, p0, analytic)
    return _collapsed_rows(head(rows, c), analytic, p0, m, figures, nodes, share, out, pulse_scratch)


def cast_seabed_analytic(target: CastScene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                         shadow_rays: bool = True, collapse: bool = False, census: dict | None = None) -> Hits:
    """:func:`scanner_sim.rays.cast.cast_beams`, with Embree casting only what it must: every pulse's axis, and
    the other sub-rays and shadow rays of the pulses :func:`scanner_sim.rays.seabed_kernels.analytic_block` cannot
    prove. A proven pulse's sub-rays meet the seabed triangles the height field puts under them, at the distance the
    ray-plane intersection gives (rounded to float32 as Embree's), and nothing can stand between its hits and the
    receiver. The hit rows are made by the same kernel as ``cast_beams``'s, so they differ from it by float32
    rounding of the distances at most. Same arguments and result; a scene without a height field is cast as
    ``cast_beams`` casts it. ``collapse``: each block's hits go through :func:`collapse_simple` while in cache.
    ``census``: counts added to it, ``"proven"`` (pulses found analytically), ``"proven_missed"`` (pulses proven to
    meet nothing) and ``"axis_on_seabed"`` (pulses whose axis met the height field first, the proof's
    precondition)."""
    grid, caster = target.seabed_grid, target.caster
    if grid is None:
        hits = cast_beams(target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry, shadow_rays)
        return collapse_simple(hits) if collapse else hits
    n_pulses, m = beam_origin.shape[0], pattern.count
    rays, layout, faces, view = kernel_inputs(target.scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir,
                                              pattern, geometry)
    block = max(1, AUTO_BLOCK_RAYS // m)
    size = min(n_pulses, block) * m  # every block's scratch, fetched once (a workspace call is ~10 us)
    rows = _scratch(caster, "auto_rows", size)
    o32_all = caster.workspace("origins32", (size, 3), np.float32)
    d32_all = caster.workspace("dirs32", (size, 3), np.float32)
    prim_all = caster.workspace("auto_prim", (size,), np.int32)
    tfar_all = caster.workspace("auto_tfar", (size,), np.float32)
    shadows = ShadowRays(caster.workspace("shadow_origins32", (size, 3), np.float32),
                         caster.workspace("shadow_dirs32", (size, 3), np.float32),
                         caster.workspace("shadow_length32", (size,), np.float32))
    out = _scratch(caster, "auto_out", size) if collapse else None
    figure_scratch = (caster.workspace("auto_figures", (size // m, 4), np.float64),
                      caster.workspace("auto_nodes", (size // m, 2), np.float64),
                      caster.workspace("auto_share", (size // m, 2), np.float64),
                      caster.workspace("auto_kept", (size,), np.int32),
                      (caster.workspace("auto_energy", (m,), np.float64), caster.workspace("auto_tau", (m,), np.float64),
                       caster.workspace("auto_own_nodes", (2,), np.float64),
                       caster.workspace("auto_own_share", (2,), np.float64)))
    segments = caster.workspace("auto_segments", (7, 2 * m), np.float64)
    left_o = caster.workspace("auto_left_origins32", (size, 3), np.float32)
    left_d = caster.workspace("auto_left_dirs32", (size, 3), np.float32)
    parts = []
    for p0 in range(0, n_pulses, block):
        p1 = min(n_pulses, p0 + block)
        b = (p1 - p0) * m
        o32, d32, prim, tfar = o32_all[:b], d32_all[:b], prim_all[:b], tfar_all[:b]
        subrays_local32(rays, p0, p1, layout, o32, d32)
        axis_prim, axis_tfar = caster.first_hits_raw(np.ascontiguousarray(o32[::m]), np.ascontiguousarray(d32[::m]))
        analytic = np.empty(p1 - p0, bool)
        analytic_block(o32, d32, axis_prim, axis_tfar, p0, rays.rx, grid, shadow_rays, prim, tfar, analytic, segments)
        if census is not None:
            on_seabed = (axis_prim >= grid.face0) & (axis_prim < grid.face0 + grid.plane.shape[0])
            missed = analytic & (axis_prim < 0)
            census["proven"] = census.get("proven", 0) + int(analytic.sum() - missed.sum())
            census["proven_missed"] = census.get("proven_missed", 0) + int(missed.sum())
            census["axis_on_seabed"] = census.get("axis_on_seabed", 0) + int(on_seabed.sum())
        k = _left_to_embree(o32, d32, analytic, m, left_o, left_d)
        if k:
            _embree_answers(prim, tfar, analytic, m, *caster.first_hits_raw(left_o[:k], left_d[:k]))
        if collapse:
            k = _collapse_block(caster, prim, tfar, analytic, p0, rays, layout, faces, view, shadow_rays, rows,
                                shadows, out, figure_scratch)
            parts.append(Hits.from_columns(head(out, k), p1 - p0, m, copy=True))
            continue
        c = hit_block(prim, tfar, p0 * m, 0, rays, layout, faces, view, rows, shadows)
        if shadow_rays:
            _cast_unproven_shadows(caster, rows, shadows, c, p0, analytic)
        part = Hits.from_columns(head(rows, c), p1 - p0, m, copy=True)
        np.arccos(part.incidence_rad, out=part.incidence_rad)
        parts.append(part)
    if not parts:
        return cast_beams(target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry, shadow_rays)
    return Hits.concatenate(parts, n_pulses)


def cast_auto(target: CastScene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
              shadow_rays: bool = True) -> Hits:
    """:func:`scanner_sim.rays.cast.cast_beams` for the ``auto`` level: ``balanced``'s hits, the seabed's found
    analytically where that is proven exact (:func:`cast_seabed_analytic`), each simple pulse's echoes collapsed
    to two (:func:`collapse_simple`, block by block). Same arguments and result; rows in scan order."""
    return cast_seabed_analytic(target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                                shadow_rays, collapse=True)


def auto_decisions(target: CastScene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                   shadow_rays: bool = True) -> dict:
    """What :func:`cast_auto` decides for these pulses (same arguments), counted: ``pulses``; ``proven``: hits
    found on the height field and no shadow ray cast; ``proven_missed``: proven to meet nothing, no sub-ray but the
    axis cast; ``axis_on_seabed``: axes that met the height field first
    (the others, on an object or on nothing, are cast as ``balanced`` casts them); ``simple``: pulses whose echoes
    are collapsed to two (:func:`~scanner_sim.rays.collapse.simple_pulses`); ``no_hit``: pulses none of whose
    sub-rays met anything (no echo to model); ``no_grid``: why no pulse can be proven
    (:func:`~scanner_sim.rays.seabed_grid.no_grid_reason`), None where the scene has its proof grid."""
    counts = {"pulses": int(beam_origin.shape[0]), "proven": 0, "proven_missed": 0, "axis_on_seabed": 0}
    hits = cast_seabed_analytic(target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                                shadow_rays, census=counts)
    counts["simple"] = int(simple_pulses(hits).sum())
    counts["no_hit"] = int((np.bincount(hits.pulse_index, minlength=hits.n_pulses) == 0).sum())
    counts["no_grid"] = None if target.seabed_grid is not None else no_grid_reason(target.scene)
    return counts


@dataclass(frozen=True)
class AutoCast(BeamCast):
    """The ``auto`` level's ray stage bound to its pass (:func:`cast_auto`)."""

    def __call__(self, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir) -> Hits:
        return cast_auto(self.target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, self.pattern, self.geometry,
                         self.shadow_rays)

    def decisions(self, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir) -> dict:
        """:func:`auto_decisions` of these pulses."""
        return auto_decisions(self.target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, self.pattern,
                              self.geometry, self.shadow_rays)
