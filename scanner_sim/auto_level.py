"""The ``auto`` fidelity level's ray stage: cast as ``balanced`` casts, but give a simple footprint two echoes.

The physics' cost goes with the echoes, one per sub-ray hit; the rays are cheap beside it. A pulse is *simple*
when all of its sub-rays hit one object within :data:`SIMPLE_SPREAD_M` of echo range (a twentieth of the 10 ns
pulse's 1.1 m, under half of one 1 ns sample). Its echo, the pulse shape summed over the sub-ray echoes, is then
the pulse spread by a distribution of delay far narrower than the pulse, and the two-point Gauss quadrature of
that distribution (its energy, mean, variance and skewness) gives the same echo to the fourth order in the
spread over the pulse width: two echoes where ``balanced`` has 19. Each keeps the footprint's energy share and
beam share; the axis hit stays as cast, with no energy, for the pulse's truth and coverage footprint. Every
other pulse (an edge, two objects, a footprint stretched over range at grazing incidence) keeps its sub-rays.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from . import _raykernels
from ._raykernels import clear_blocked, hit_block
from .beams import BeamPattern
from .raycast import Hits, cast_beams

#: [m] Largest spread of a simple pulse's echo ranges: the column-cut bin (fidelity.SUBRAY_CUT_BIN_M), under half
#: the 0.11 m of range one 1 ns sample spans and a twentieth of the 10 ns pulse's 1.1 m.
SIMPLE_SPREAD_M = 0.05


def _echo_range(hits: Hits) -> np.ndarray:
    return 0.5 * (hits.range_m + hits.rx_distance_m)  # survey.hit_echo_range_m


def simple_pulses(hits: Hits) -> np.ndarray:
    """(n_pulses,) bool: every sub-ray of the pulse hit, all on one object, their echo ranges within
    :data:`SIMPLE_SPREAD_M` (``hits`` in scan order, pulse-major)."""
    n = hits.n_pulses
    simple = np.bincount(hits.pulse_index, minlength=n) == hits.n_subrays
    if not simple.any():
        return simple
    starts = np.flatnonzero(np.r_[True, hits.pulse_index[1:] != hits.pulse_index[:-1]])
    owner = hits.pulse_index[starts]

    def spread(values):
        out = np.full(n, np.inf)
        out[owner] = np.maximum.reduceat(values, starts) - np.minimum.reduceat(values, starts)
        return out

    return simple & (spread(hits.object_id.astype(np.float64)) == 0.0) & (spread(_echo_range(hits)) < SIMPLE_SPREAD_M)


def two_point_rule(energy: np.ndarray, delay: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two-point Gauss quadrature of the discrete distributions ``energy`` (n, m) >= 0 over ``delay`` (n, m), rows
    with energy: nodes (n, 2) and each node's share of the energy (n, 2), exact for polynomials of degree 3.

    In standard units z of a row (mean 0, variance 1, third moment g) the nodes are the roots of the orthogonal
    polynomial z^2 - g z - 1, z = (g -/+ sqrt(g^2 + 4)) / 2, with shares z2 / (z2 - z1) and -z1 / (z2 - z1)."""
    n = energy.shape[0]
    nodes, share = np.empty((n, 2)), np.empty((n, 2))
    for i in range(n):
        _rule(energy[i], delay[i], nodes[i], share[i])
    return nodes, share


@numba.njit(cache=True, nogil=True)
def _rule(energy, delay, nodes, share):
    """:func:`two_point_rule` of one distribution into ``nodes`` (2,) and ``share`` (2,)."""
    total = 0.0
    mean = 0.0
    for k in range(energy.shape[0]):
        total += energy[k]
        mean += energy[k] * delay[k]
    mean /= total
    var, third = 0.0, 0.0
    for k in range(energy.shape[0]):
        d = delay[k] - mean
        var += energy[k] * d * d
        third += energy[k] * d * d * d
    sd = math.sqrt(var / total)
    g = third / total / sd**3 if sd > 0.0 else 0.0
    root = math.sqrt(g * g + 4.0)
    z1, z2 = 0.5 * (g - root), 0.5 * (g + root)
    nodes[0], nodes[1] = mean + sd * z1, mean + sd * z2
    share[0], share[1] = z2 / root, -z1 / root


@numba.njit(cache=True, nogil=True)
def _collapse(first, m, weight, reflectance, incidence, seen, range_m, rx_m, nodes, share, beam, rho_mean, cosine,
              mean_range):
    """Per simple pulse (its rows ``first[i]`` to ``first[i] + m``): its two echoes' delays ``nodes`` and energy
    ``share`` (:func:`_rule` over echo range), beam share, beam-weighted reflectance, effective cosine and
    beam-weighted mean range; ``beam`` 0 where no light comes back."""
    energy = np.empty(m)
    tau = np.empty(m)
    for i in range(first.shape[0]):
        total, w_sum, rho_sum, r_sum = 0.0, 0.0, 0.0, 0.0
        for k in range(m):
            r = first[i] + k
            energy[k] = weight[r] * reflectance[r] * math.cos(incidence[r]) * seen[r]
            tau[k] = 0.5 * (range_m[r] + rx_m[r])
            total += energy[k]
            w_sum += weight[r]
            rho_sum += weight[r] * reflectance[r]
            r_sum += weight[r] * range_m[r]
        if total <= 0.0:
            beam[i] = 0.0
            continue
        _rule(energy, tau, nodes[i], share[i])
        beam[i] = w_sum
        rho_mean[i] = rho_sum / w_sum
        cosine[i] = min(1.0, total / rho_sum)
        mean_range[i] = r_sum / w_sum


@numba.njit(cache=True, nogil=True)
def _figures(start, stop, m, fields, angles, energy, tau, nodes, share):
    """The simple-pulse figures of one pulse's rows start .. stop - 1 of ``fields`` (:data:`_FIELDS` order;
    incidence angles [rad] if ``angles``, else their cosines): (beam, rho_mean, cosine, mean_range) with beam -1
    when the pulse is not simple (:func:`simple_pulses`' test) and 0 when no light comes back; for a lit simple
    pulse its two echoes' delays ``nodes`` and energy ``share`` (:func:`_collapse`). ``energy``, ``tau``: (m,)
    scratch."""
    _, _, range_m, _, _, incidence, reflectance, _, object_id, seen, weight, rx_m = fields
    if stop - start != m:
        return -1.0, 0.0, 0.0, 0.0
    lo, hi = np.inf, -np.inf
    for r in range(start, stop):
        if object_id[r] != object_id[start]:
            return -1.0, 0.0, 0.0, 0.0
        e = 0.5 * (range_m[r] + rx_m[r])
        lo, hi = min(lo, e), max(hi, e)
    if not hi - lo < SIMPLE_SPREAD_M:
        return -1.0, 0.0, 0.0, 0.0
    total, w_sum, rho_sum, r_sum = 0.0, 0.0, 0.0, 0.0
    for k in range(m):
        r = start + k
        cos_r = math.cos(incidence[r]) if angles else incidence[r]
        energy[k] = weight[r] * reflectance[r] * cos_r * seen[r]
        tau[k] = 0.5 * (range_m[r] + rx_m[r])
        total += energy[k]
        w_sum += weight[r]
        rho_sum += weight[r] * reflectance[r]
        r_sum += weight[r] * range_m[r]
    if total <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    _rule(energy, tau, nodes, share)
    return w_sum, rho_sum / w_sum, min(1.0, total / rho_sum), r_sum / w_sum


@numba.njit(cache=True, nogil=True)
def _emit(start, stop, fields, angles, out, o, beam, rho_mean, cosine, mean_range, nodes, share):
    """Write one pulse's rows start .. stop - 1 of ``fields`` into ``out`` from row o as :func:`collapse_simple`
    keeps them (all as they are if ``beam`` < 0, else the axis row with no energy share and, with light, its two
    echoes; incidence out in radians); returns the next free row."""
    (pi, sub, rng, pt, nrm, inc, refl, lab, obj, seen, wt, rx) = fields
    (po, so, ro, pto, no, io, fo, lo, oo, sno, wo, rxo) = out
    simple = beam >= 0.0
    for r in range(start, stop):
        if simple and sub[r] != 0:
            continue
        copies = 1 if not simple or beam == 0.0 else 3
        for c in range(copies):
            po[o], so[o], ro[o], fo[o], lo[o], oo[o] = pi[r], sub[r], rng[r], refl[r], lab[r], obj[r]
            io[o] = inc[r] if angles else math.acos(inc[r])
            for a in range(3):
                pto[o, a] = pt[r, a]
                no[o, a] = nrm[r, a]
            sno[o], wo[o], rxo[o] = seen[r], wt[r], rx[r]
            if simple:
                if c == 0:
                    wo[o] = 0.0
                else:
                    so[o] = c
                    wo[o] = beam * share[c - 1]
                    fo[o] = rho_mean
                    io[o] = math.acos(cosine)
                    sno[o] = 1.0
                    ro[o] = mean_range
                    rxo[o] = 2.0 * nodes[c - 1] - mean_range
            o += 1
    return o


@numba.njit(cache=True, nogil=True)
def _collapse_rows(fields, angles, m, out):
    """:func:`collapse_simple` of the pulse-major rows ``fields`` into ``out`` (room for every row); returns the
    rows written."""
    pulse = fields[0]
    energy, tau, nodes, share = np.empty(m), np.empty(m), np.empty(2), np.empty(2)
    start, o = 0, 0
    while start < pulse.shape[0]:
        stop = start + 1
        while stop < pulse.shape[0] and pulse[stop] == pulse[start]:
            stop += 1
        beam, rho_mean, cosine, mean_range = _figures(start, stop, m, fields, angles, energy, tau, nodes, share)
        o = _emit(start, stop, fields, angles, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
        start = stop
    return o


_FIELDS = ("pulse_index", "subray_index", "range_m", "point", "normal", "incidence_rad", "reflectance", "label",
           "object_id", "receiver_weight", "weight", "rx_distance_m")


def _collapsed(fields: tuple, angles: bool, n: int, m: int) -> Hits:
    """:func:`collapse_simple` of the rows ``fields`` (:data:`_FIELDS` order) of ``n`` pulses, into fresh arrays."""
    out = tuple(np.empty(a.shape, a.dtype) for a in fields)
    k = _collapse_rows(fields, angles, m, out)
    return Hits(**{f: a[:k].copy() for f, a in zip(_FIELDS, out)}, n_pulses=n, n_subrays=m)


def collapse_simple(hits: Hits) -> Hits:
    """``hits`` with each simple pulse's sub-rays (:func:`simple_pulses`) replaced by its axis hit as cast with
    no energy share (sub-ray 0, weight 0) and two echoes (sub-rays 1 and 2) of its :func:`two_point_rule` over
    echo range, weighted by energy (weight x reflectance x cosine of incidence x receiver weight, the echo
    weight of survey.pulse_batch). Each echo carries its share of the footprint's beam share, the footprint's
    beam-weighted reflectance, and the cosine that gives it its share of the energy; its outgoing leg is the
    footprint's beam-weighted mean range (where a footprint within one 5 cm bin cuts the water column,
    fidelity.column_cuts), its return leg what makes up its delay. Other pulses keep their rows. ``hits`` as
    :func:`scanner_sim.raycast.cast_beams` gives them: pulse-major, sub-rays ascending; the result too. Compiled
    (two passes over the rows); :func:`collapse_simple_numpy` is the same in numpy."""
    return _collapsed(tuple(getattr(hits, f) for f in _FIELDS), True, hits.n_pulses, hits.n_subrays)


def collapse_simple_numpy(hits: Hits) -> Hits:
    """``hits`` with each simple pulse's sub-rays (:func:`simple_pulses`) replaced by its axis hit as cast with
    no energy share (sub-ray 0, weight 0) and two echoes (sub-rays 1 and 2) of its :func:`two_point_rule` over
    echo range, weighted by energy (weight x reflectance x cosine of incidence x receiver weight, the echo
    weight of survey.pulse_batch). Each echo carries its share of the footprint's beam share, the footprint's
    beam-weighted reflectance, and the cosine that gives it its share of the energy; its outgoing leg is the
    footprint's beam-weighted mean range (where a footprint within one 5 cm bin cuts the water column,
    fidelity.column_cuts), its return leg what makes up its delay. Other pulses keep their rows. ``hits`` as
    :func:`scanner_sim.raycast.cast_beams` gives them: pulse-major, sub-rays ascending; the result too. The numpy
    form of :func:`collapse_simple`, kept as its check."""
    m = hits.n_subrays
    simple = simple_pulses(hits)
    rows = simple[hits.pulse_index]
    first = np.flatnonzero(rows)[::m]  # each simple pulse's axis row; its m rows follow
    k = first.size
    nodes, share = np.empty((k, 2)), np.empty((k, 2))
    beam, rho_mean, cosine, mean_range = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    _collapse(first, m, hits.weight, hits.reflectance, hits.incidence_rad, hits.receiver_weight, hits.range_m,
              hits.rx_distance_m, nodes, share, beam, rho_mean, cosine, mean_range)
    lit = beam > 0.0
    # Rows kept: every row of the other pulses; of a simple pulse its axis row, three times over if it has light.
    repeat = np.where(rows, 0, 1)
    repeat[first] = np.where(lit, 3, 1)
    take = np.repeat(np.arange(len(hits)), repeat)
    out = {f.name: getattr(hits, f.name)[take] for f in dataclasses.fields(Hits)
           if f.name not in ("n_pulses", "n_subrays")}
    axis_at = (np.cumsum(repeat) - repeat)[first]  # each axis row's place in the result
    out["weight"][axis_at] = 0.0
    at = (axis_at[lit][:, None] + np.array([1, 2])).ravel()
    out["subray_index"][at] = np.tile(np.array([1, 2], out["subray_index"].dtype), int(lit.sum()))
    out["weight"][at] = (beam[lit, None] * share[lit]).ravel()
    out["reflectance"][at] = np.repeat(rho_mean[lit], 2)
    out["incidence_rad"][at] = np.repeat(np.arccos(cosine[lit]), 2)
    out["receiver_weight"][at] = 1.0
    out["range_m"][at] = np.repeat(mean_range[lit], 2)
    out["rx_distance_m"][at] = (2.0 * nodes[lit] - mean_range[lit, None]).ravel()
    return Hits(**out, n_pulses=hits.n_pulses, n_subrays=m)


#: [m] Side of the coarse cells over which :func:`seabed_grid` bounds the seabed's slope and the other objects.
COARSE_CELL_M = 0.1
#: [m] Side of the blocks of coarse cells over which :func:`seabed_grid` keeps the highest point of anything.
SUPER_CELL_M = 1.0
#: Sub-rays per block of :func:`cast_seabed_analytic`.
AUTO_BLOCK_RAYS = 32768


def seabed_grid(scene, caster):
    """The :class:`scanner_sim._raykernels.SeabedGrid` of ``scene``'s seabed in ``caster``'s local frame, or None
    where the scene has no height field or its seabed faces are not the height field's own, in its order."""
    from ._raykernels import SeabedGrid, rasterise_tops, seabed_planes

    hf = scene.heightfield
    seabeds = [o for o in scene.objects if o.kind == "seabed"]
    if hf is None or len(seabeds) != 1:
        return None
    sb = seabeds[0]
    ny, nx = hf.shape
    cells = (nx - 1) * (ny - 1)
    faces = scene.faces[sb.face_start:sb.face_stop]
    if faces.shape[0] != 2 * cells:
        return None
    _, expected = hf.mesh()
    if not np.array_equal(faces - faces.min(), expected):
        return None
    k = max(1, round(COARSE_CELL_M / hf.spacing_m))
    cy, cx = -(-(ny - 1) // k), -(-(nx - 1) // k)

    def coarse_max(fine):  # (ny - 1, nx - 1) -> (cy, cx)
        padded = np.full((cy * k, cx * k), -np.inf)
        padded[:ny - 1, :nx - 1] = fine
        return padded.reshape(cy, k, cx, k).max(axis=(1, 3))

    normal = scene.face_normal[sb.face_start:sb.face_stop]
    gradient = np.empty((cy, cx, 4))
    for axis in (0, 1):  # dz/dx, dz/dy of each seabed triangle: -n_x / n_z, -n_y / n_z
        g = (-normal[:, axis] / normal[:, 2]).reshape(2, ny - 1, nx - 1)
        gradient[:, :, 2 * axis] = -coarse_max(-g.min(axis=0))
        gradient[:, :, 2 * axis + 1] = coarse_max(g.max(axis=0))
    z = caster.vertices[faces.min():faces.min() + nx * ny, 2].astype(np.float64).reshape(ny, nx)
    node_top = np.maximum(np.maximum(z[:-1, :-1], z[:-1, 1:]), np.maximum(z[1:, :-1], z[1:, 1:]))
    x0, y0 = hf.x0_m - scene.local_origin[0], hf.y0_m - scene.local_origin[1]
    object_top = np.full((cy, cx), -np.inf)
    size = k * hf.spacing_m
    rasterise_tops(caster.vertices, caster.faces, 0, sb.face_start, x0, y0, size, object_top)
    rasterise_tops(caster.vertices, caster.faces, sb.face_stop, caster.faces.shape[0], x0, y0, size, object_top)
    top = np.maximum(coarse_max(node_top), object_top)
    sk = max(1, round(SUPER_CELL_M / (k * hf.spacing_m)))
    sy, sx = -(-cy // sk), -(-cx // sk)
    padded = np.full((sy * sk, sx * sk), -np.inf)
    padded[:cy, :cx] = top
    super_top = padded.reshape(sy, sk, sx, sk).max(axis=(1, 3))
    plane = np.empty((2 * cells, 4))
    seabed_planes(caster.vertices, caster.faces, sb.face_start, sb.face_stop, plane)
    return SeabedGrid(float(x0), float(y0), float(hf.spacing_m), int(nx), int(ny), int(sb.face_start), int(k),
                      gradient, coarse_max(node_top), object_top, float(caster.vertices[:, 2].max()) + 1e-3, plane,
                      int(sk), super_top)


def _grid_of(caster, scene):
    """:func:`seabed_grid` once per caster (its scene)."""
    cached = getattr(caster, "_auto_seabed_grid", None)
    if cached is None or cached[0] is not scene:
        cached = (scene, seabed_grid(scene, caster))
        caster._auto_seabed_grid = cached
    return cached[1]


@numba.njit(cache=True, nogil=True)
def _unproven_rows(prim, tfar, analytic, p0, rays, layout, faces, apex_behind, cos_half_fov, rows, shadows):
    """:func:`scanner_sim._raykernels.hit_block` over the block's pulses that ``analytic`` leaves to Embree:
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
    """The block's rows as :func:`collapse_simple` keeps them, pulse by pulse into ``out`` (:data:`_FIELDS` order,
    room for every sub-ray): a proven pulse's hit rows made (:func:`scanner_sim._raykernels.hit_block`) and
    collapsed while in cache, the others' collapsed from ``unproven`` (their rows, shadow rays applied, in
    :data:`_FIELDS` order with incidence cosines). Returns the rows written."""
    m = layout.xy.shape[0]
    one = _raykernels.HitRows(np.empty(m, np.int64), np.empty(m, np.int32), np.empty(m), np.empty((m, 3)),
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
            beam, rho_mean, cosine, mean_range = _figures(0, c, m, one_fields, False, energy, tau, nodes, share)
            o = _emit(0, c, one_fields, False, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
        else:
            start = u
            while u < unproven_pulse.shape[0] and unproven_pulse[u] == p:
                u += 1
            if u > start:
                beam, rho_mean, cosine, mean_range = _figures(start, u, m, unproven, False, energy, tau, nodes,
                                                              share)
                o = _emit(start, u, unproven, False, out, o, beam, rho_mean, cosine, mean_range, nodes, share)
    return o


def _scratch_rows(caster, n: int):
    """HitRows of n rows in ``caster``'s per-thread workspace (reused block after block: no fresh pages)."""
    from ._raykernels import HitRows

    shapes = dict(point=(n, 3), normal=(n, 3))
    return HitRows(*(caster.workspace(f"auto_rows_{name}", shapes.get(name, (n,)), a.dtype)
                     for name, a in zip(HitRows._fields, HitRows.empty(0))))


def _fields_of(rows, c: int) -> tuple:
    """The first c rows of HitRows in :data:`_FIELDS` order (incidence as cosines)."""
    return (rows.pulse[:c], rows.sub[:c], rows.range_m[:c], rows.point[:c], rows.normal[:c], rows.cos_inc[:c],
            rows.reflectance[:c], rows.label[:c], rows.object_id[:c], rows.seen[:c], rows.weight[:c],
            rows.rx_dist[:c])


#: The dtype of each field of :data:`_FIELDS` (as scanner_sim.raycast.cast_beams gives them).
_DTYPES = (np.int64, np.int32, np.float64, np.float64, np.float32, np.float64, np.float64, np.int16, np.int32,
           np.float64, np.float64, np.float32)


def _scratch_out(caster, n: int) -> tuple:
    """Room for n rows in :data:`_FIELDS` order, in ``caster``'s per-thread workspace."""
    return tuple(caster.workspace(f"auto_out_{f}", (n, 3) if f in ("point", "normal") else (n,), t)
                 for f, t in zip(_FIELDS, _DTYPES))


def _concatenate(parts: list[Hits], n_pulses: int, m: int) -> Hits:
    """The blocks' hits as one, in their order."""
    if len(parts) == 1:
        return dataclasses.replace(parts[0], n_pulses=n_pulses)
    return Hits(**{f: np.concatenate([getattr(h, f) for h in parts]) for f in _FIELDS}, n_pulses=n_pulses,
                n_subrays=m)


def cast_seabed_analytic(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern,
                         geometry, shadow_rays: bool = True, collapse: bool = False) -> Hits:
    """:func:`scanner_sim.raycast.cast_beams`, with Embree casting only what it must: every pulse's axis, and
    the other sub-rays and shadow rays of the pulses :func:`scanner_sim._raykernels.analytic_block` cannot prove.
    A proven pulse's sub-rays meet the seabed triangles the height field puts under them, at the distance the
    ray-plane intersection gives (rounded to float32 as Embree's), and nothing can stand between its hits and the
    receiver. The hit rows are made by the same kernel as ``cast_beams``'s, so they differ from it by float32
    rounding of the distances at most. Same arguments and result; a scene without a height field is cast as
    ``cast_beams`` casts it. ``collapse``: each block's hits go through :func:`collapse_simple` while in cache."""
    grid = _grid_of(caster, scene)
    if grid is None:
        hits = cast_beams(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                          shadow_rays)
        return collapse_simple(hits) if collapse else hits
    from . import _raykernels as kernels
    from .beams import perpendicular_basis
    from .raycast import ReceiverCone, shadow_offset_m

    n_pulses, m = beam_origin.shape[0], pattern.count
    beam_dir = np.ascontiguousarray(beam_dir, dtype=np.float64)
    u, v = perpendicular_basis(beam_dir, np.asarray(shaft_dir, float))
    rays = kernels.PulseRays(np.ascontiguousarray(beam_origin - scene.local_origin), beam_dir, u, v,
                             np.ascontiguousarray(rx_origin - scene.local_origin),
                             np.ascontiguousarray(rx_dir, dtype=np.float64))
    layout = kernels.SubrayLayout(np.ascontiguousarray(pattern.xy), pattern.weight, 0.5 * geometry.beam_diameter_m,
                                  math.tan(0.5 * geometry.beam_divergence_full_rad))
    faces = kernels.SceneFaces(scene.face_normal, scene.face_reflectance, scene.face_label, scene.face_object,
                               scene.local_origin, shadow_offset_m(scene.local_extent_m))
    cone = ReceiverCone.from_geometry(geometry)
    block = max(1, AUTO_BLOCK_RAYS // m)
    size = min(n_pulses, block) * m  # every block's scratch, fetched once (a workspace call is ~10 us)
    rows = _scratch_rows(caster, size)
    o32_all = caster.workspace("origins32", (size, 3), np.float32)
    d32_all = caster.workspace("dirs32", (size, 3), np.float32)
    prim_all = caster.workspace("auto_prim", (size,), np.int32)
    tfar_all = caster.workspace("auto_tfar", (size,), np.float32)
    shadows_all = kernels.ShadowRays(caster.workspace("shadow_origins32", (size, 3), np.float32),
                                     caster.workspace("shadow_dirs32", (size, 3), np.float32),
                                     caster.workspace("shadow_length32", (size,), np.float32))
    out = _scratch_out(caster, size) if collapse else None
    rest_sub = np.arange(1, m)
    parts = []
    for p0 in range(0, n_pulses, block):
        p1 = min(n_pulses, p0 + block)
        b = (p1 - p0) * m
        o32, d32, prim, tfar = o32_all[:b], d32_all[:b], prim_all[:b], tfar_all[:b]
        kernels.subrays_local32(rays, p0, p1, layout, o32, d32)
        axis_prim, axis_tfar = caster.first_hits_raw(np.ascontiguousarray(o32[::m]), np.ascontiguousarray(d32[::m]))
        analytic = np.empty(p1 - p0, bool)
        kernels.analytic_block(o32, d32, axis_prim, axis_tfar, p0, rays.rx, grid, shadow_rays, prim, tfar, analytic)
        cast = np.flatnonzero(~analytic)
        if cast.size:
            at = (cast[:, None] * m + rest_sub).ravel()
            prim[at], tfar[at] = caster.first_hits_raw(o32[at], d32[at])
        shadows = shadows_all
        if collapse:
            c = _unproven_rows(prim, tfar, analytic, p0, rays, layout, faces, cone.apex_behind_m, cone.cos_half_fov,
                               rows, shadows)
            if shadow_rays and c:
                occluded = caster.occluded_raw(shadows.origin[:c], shadows.direction[:c], shadows.length[:c])
                clear_blocked(occluded, shadows.length[:c], rows.seen, 0)
            k = _block_collapsed(prim, tfar, analytic, p0, rays, layout, faces, cone.apex_behind_m,
                                 cone.cos_half_fov, _fields_of(rows, c), out)
            parts.append(Hits(**{f: a[:k].copy() for f, a in zip(_FIELDS, out)}, n_pulses=p1 - p0, n_subrays=m))
            continue
        c = kernels.hit_block(prim, tfar, p0 * m, 0, rays, layout, faces, cone.apex_behind_m, cone.cos_half_fov,
                              rows, shadows)
        if shadow_rays and c:
            need = kernels.unproven_shadows(rows.pulse[:c], p0, analytic, shadows.length[:c])
            if need.size:
                occluded = caster.occluded_raw(shadows.origin[need], shadows.direction[need], shadows.length[need])
                rows.seen[need[occluded >= 0]] = 0.0
        part = Hits(**dict(zip(_FIELDS, (a.copy() for a in _fields_of(rows, c)))), n_pulses=p1 - p0, n_subrays=m)
        np.arccos(part.incidence_rad, out=part.incidence_rad)
        parts.append(part)
    if not parts:
        return cast_beams(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern, geometry,
                          shadow_rays)
    return _concatenate(parts, n_pulses, m)


def cast_auto(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern: BeamPattern, geometry,
              shadow_rays: bool = True) -> Hits:
    """:func:`scanner_sim.raycast.cast_beams` for the ``auto`` level: ``balanced``'s hits, the seabed's found
    analytically where that is proven exact (:func:`cast_seabed_analytic`), each simple pulse's echoes collapsed
    to two (:func:`collapse_simple`, block by block). Same arguments and result; rows in scan order."""
    return cast_seabed_analytic(caster, scene, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, pattern,
                                geometry, shadow_rays, collapse=True)
