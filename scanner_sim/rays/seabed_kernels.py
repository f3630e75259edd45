"""Numba kernels of the proofs on the seabed's coarse grid (scanner_sim.rays.seabed_grid): that nothing can stand in a
pulse's sub-rays' way or between their hits and the receiver, the ``auto`` level's ray-plane hits of the pulses it
proves (scanner_sim.rays.auto), and the shadow rays any level need not cast (scanner_sim.rays.cast.cast_beams).
Compiled on first use and cached on disk.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from muls.infra.borrowed import borrowed
from muls.infra.runtime import kernel


class SeabedGrid(NamedTuple):
    """The seabed height field as the proofs of this module see it (scanner_sim.rays.seabed_grid.seabed_grid).

    x0, y0 [m]: local-frame position of node (0, 0); spacing [m]; nx, ny: nodes; face0: the scene's first seabed
    face; cell_face (2 (nx - 1)(ny - 1),): the seabed face, counted from face0, of each triangle of the height field
    (cell (i, j)'s lower triangle at i (nx - 1) + j, its upper one at that plus (nx - 1)(ny - 1), as
    scanner_sim.world.terrain.HeightField.mesh orders them), -1 where the cell is a gap (no data, no triangle);
    empty where the height field has no gaps (each triangle is then the face of its own number);
    k: height-field cells per side of a coarse cell. Per coarse cell (cy, cx): gradient (cy, cx, 4), the least and
    greatest dz/dx and dz/dy of its seabed triangles; seabed_top [m], its highest node (-inf: gaps only);
    object_top [m], the highest point of any other triangle whose xy box overlaps it (-inf: none).
    z_top [m]: above it there is no geometry at all. plane (seabed faces, 4): each seabed face's plane n . x = w
    as (n, w), n the (unnormalised) cross product of its float32 edges, in face order from face0. super_top
    (sy, sx) [m]: the highest point of any triangle over each block of super_k x super_k coarse cells. object_id: the
    seabed's index in the scene's objects. z_bottom [m]: below it there is no geometry at all; holds_all: every
    triangle of the scene lies over the height field's extent (nothing beyond it)."""

    x0: float
    y0: float
    spacing: float
    nx: int
    ny: int
    face0: int
    cell_face: np.ndarray
    k: int
    gradient: np.ndarray
    seabed_top: np.ndarray
    object_top: np.ndarray
    z_top: float
    plane: np.ndarray
    super_k: int
    super_top: np.ndarray
    object_id: int
    z_bottom: float
    holds_all: bool


@kernel(nogil=True)
def rasterise_tops(vertices, faces, first, stop, x0, y0, size, top):
    """top[I, J] = max(top, highest z) of the triangles ``faces[first:stop]`` (indices into ``vertices``, local
    float32) whose xy box overlaps coarse cell (I, J) of side ``size`` [m] from (x0, y0)."""
    cy, cx = top.shape
    for f in range(first, stop):
        xmin, xmax, ymin, ymax, zmax = np.inf, -np.inf, np.inf, -np.inf, -np.inf
        for c in range(3):
            v = faces[f, c]
            x, y, z = np.float64(vertices[v, 0]), np.float64(vertices[v, 1]), np.float64(vertices[v, 2])
            xmin, xmax, ymin, ymax, zmax = min(xmin, x), max(xmax, x), min(ymin, y), max(ymax, y), max(zmax, z)
        j0, j1 = math.floor((xmin - x0) / size), math.floor((xmax - x0) / size)
        i0, i1 = math.floor((ymin - y0) / size), math.floor((ymax - y0) / size)
        if j1 < 0 or i1 < 0 or j0 >= cx or i0 >= cy:
            continue
        for i in range(max(i0, 0), min(i1, cy - 1) + 1):
            for j in range(max(j0, 0), min(j1, cx - 1) + 1):
                if zmax > top[i, j]:
                    top[i, j] = zmax


@kernel(inline="always")
def seabed_face_at(x0, y0, spacing, nx, ny, x, y):
    """The triangle under local (x, y) of the height field of ``nx`` x ``ny`` nodes ``spacing`` [m] apart from
    (x0, y0) (:class:`SeabedGrid`'s), numbered as its ``cell_face`` numbers them (terrain.HeightField.height's choice
    of triangle), -1 off it. Scalars only: a kernel handed the grid's arrays costs several times more per call."""
    inv_spacing = 1.0 / spacing
    fx = (x - x0) * inv_spacing
    fy = (y - y0) * inv_spacing
    if not (fx >= 0.0 and fy >= 0.0):
        return -1
    j, i = int(fx), int(fy)
    if j > nx - 2 or i > ny - 2:
        return -1
    f = i * (nx - 1) + j
    if fy - i > fx - j:  # upper triangle (a, d, c): v > u
        f += (nx - 1) * (ny - 1)
    return f


#: [m] Clearance the analytic-hit tests ask of every bound (far above float32 rounding of the local frame).
CLEARANCE_M = 1e-3
#: Most drop [blocks of ``super_top``] :func:`_bundle_misses` takes in one step (fewer where the rays run sideways).
MISS_STEP_BLOCKS = 4.0


@kernel(nogil=True)
def seabed_planes(vertices, faces, first, stop, plane):
    """plane[f - first] = (n, n . a) of faces first .. stop - 1, n = (b - a) x (c - a) in float64 of the float32
    vertices a, b, c."""
    for f in range(first, stop):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ax, ay, az = np.float64(vertices[a, 0]), np.float64(vertices[a, 1]), np.float64(vertices[a, 2])
        ex, ey, ez = vertices[b, 0] - ax, vertices[b, 1] - ay, vertices[b, 2] - az
        gx, gy, gz = vertices[c, 0] - ax, vertices[c, 1] - ay, vertices[c, 2] - az
        nx, ny, nz = ey * gz - ez * gy, ez * gx - ex * gz, ex * gy - ey * gx
        i = f - first
        plane[i, 0], plane[i, 1], plane[i, 2], plane[i, 3] = nx, ny, nz, nx * ax + ny * ay + nz * az


@kernel(nogil=True, error_model="numpy")
def _bundle_clear(grid, hx, hy, hz, z_end, wx, wy, rise, n, foot_x, foot_y, foot_r, foot_zmin):
    """Can nothing meet the n straight segments from the seabed points (hx, hy, hz)[j] up to the heights
    z_end[j], each rising ``rise[j]`` per horizontal metre along the horizontal unit direction (wx, wy)[j] away from
    its seabed point?

    True when every coarse cell of their xy box lies on the height field, no other triangle in it reaches up to
    the lowest the segments can be over it, and where its seabed can (a *touchable* cell), the seabed rises along
    each segment's direction less steeply than the least steep segment (bounded over the cell's least and greatest
    gradient and the segments' least and greatest direction components). Then no segment meets anything but at its
    seabed point: in untouchable cells it is above all there is, and in touchable ones its height over the seabed
    only grows away from that point, so once above the seabed it stays above. The xy box is taken up to the top of
    what stands within the box the segments span up to the top of the scene (``super_top``)."""
    slope_min, z_high = np.inf, -np.inf
    wx_lo, wx_hi, wy_lo, wy_hi = np.inf, -np.inf, np.inf, -np.inf  # the directions of the finite rises
    for j in range(n):
        slope_min = min(slope_min, rise[j])
        z_high = max(z_high, z_end[j])
        if rise[j] < np.inf:
            wx_lo, wx_hi, wy_lo, wy_hi = min(wx_lo, wx[j]), max(wx_hi, wx[j]), min(wy_lo, wy[j]), max(wy_hi, wy[j])
    # Their xy box: every segment starts within foot_r of the foot and runs at most ``run`` horizontally, along a
    # direction inside the box of directions, up to the top of the scene or its end; then the same up to the top
    # of what stands in that box, which bounds them more tightly (above it they are clear).
    span_x, span_y = (grid.nx - 1) * grid.spacing, (grid.ny - 1) * grid.spacing
    cap = grid.z_top
    for attempt in range(2):
        xmin, xmax, ymin, ymax = foot_x - foot_r, foot_x + foot_r, foot_y - foot_r, foot_y + foot_r
        if slope_min < np.inf:
            run = (min(cap, z_high) - foot_zmin) / slope_min
            xmin, xmax = xmin + min(wx_lo, 0.0) * run, xmax + max(wx_hi, 0.0) * run
            ymin, ymax = ymin + min(wy_lo, 0.0) * run, ymax + max(wy_hi, 0.0) * run
        if not (xmin >= grid.x0 and ymin >= grid.y0 and xmax <= grid.x0 + span_x and ymax <= grid.y0 + span_y):
            return False
        if attempt == 0:
            size = grid.super_k * grid.k * grid.spacing
            cap = -np.inf
            sy, sx = grid.super_top.shape
            for i in range(int((ymin - grid.y0) / size), min(int((ymax - grid.y0) / size), sy - 1) + 1):
                for j in range(int((xmin - grid.x0) / size), min(int((xmax - grid.x0) / size), sx - 1) + 1):
                    cap = max(cap, grid.super_top[i, j])
            cap += CLEARANCE_M
    size = grid.k * grid.spacing
    gradient, seabed_top, object_top = grid.gradient, grid.seabed_top, grid.object_top
    cy, cx = seabed_top.shape
    j0, j1 = int((xmin - grid.x0) / size), min(int((xmax - grid.x0) / size), cx - 1)
    i0, i1 = int((ymin - grid.y0) / size), min(int((ymax - grid.y0) / size), cy - 1)
    for i in range(i0, i1 + 1):
        by0 = grid.y0 + i * size
        dy = max(by0 - foot_y, 0.0, foot_y - (by0 + size))
        for j in range(j0, j1 + 1):
            bx0 = grid.x0 + j * size
            dx = max(bx0 - foot_x, 0.0, foot_x - (bx0 + size))
            reach = math.sqrt(dx * dx + dy * dy) - foot_r  # horizontal distance every segment has covered
            low = foot_zmin + (slope_min * reach if reach > 0.0 else 0.0)  # lowest a segment can be over the cell
            if object_top[i, j] >= low - CLEARANCE_M:
                return False
            if seabed_top[i, j] < low - CLEARANCE_M:
                continue
            if slope_min == np.inf:
                continue
            # The steepest the seabed can rise along any of the directions: g . w over the cell's gradient box and
            # the box of directions (each product's extreme lies at a corner).
            gx_lo, gx_hi, gy_lo, gy_hi = gradient[i, j, 0], gradient[i, j, 1], gradient[i, j, 2], gradient[i, j, 3]
            steepest = (max(gx_lo * wx_lo, gx_lo * wx_hi, gx_hi * wx_lo, gx_hi * wx_hi)
                        + max(gy_lo * wy_lo, gy_lo * wy_hi, gy_hi * wy_lo, gy_hi * wy_hi))
            if not steepest + CLEARANCE_M * (1.0 + abs(steepest)) < slope_min:
                return False
    return True


@kernel(inline="always", error_model="numpy")
def _rising_toward(x, y, z, tx, ty, tz):
    """The segment from the seabed point (x, y, z) straight up to the point (tx, ty, tz) [m] (a receiver aperture)
    as :func:`_bundle_clear` takes it: (above, rise, wx, wy), ``above`` False where that point is not above the
    seabed point (the rest then meaningless); rise inf, (wx, wy) = 0 when it is straight above. Scalars in and out:
    a kernel that writes the bundle's arrays itself costs several times more per segment."""
    up = tz - z
    if not up > 0.0:
        return False, 0.0, 0.0, 0.0
    ex, ey = tx - x, ty - y
    h2 = ex ** 2 + ey ** 2
    if h2 > 0.0:
        inv_h = 1.0 / math.sqrt(h2)
        return True, up * inv_h, ex * inv_h, ey * inv_h
    return True, np.inf, 0.0, 0.0


@kernel(nogil=True, error_model="numpy")
def _bundle_misses(grid, origins, dirs, first, m):
    """Can none of the m rays ``origins``, ``dirs`` [first, first + m) ((k, 3) local float32, a pulse's sub-rays)
    meet anything?

    True when every ray descends and, down to where all of them lie below ``z_bottom``, no block of
    :class:`SeabedGrid`'s ``super_top`` the bundle passes over holds anything as high as the lowest the bundle can be
    there; beyond the height field's extent there is nothing (``holds_all``). Each ray is followed by its drop: at
    drop h below its origin a ray lies within r0 + h g of the axis's point at drop h (r0: the farthest origin from
    the axis's, g: the most a ray's horizontal run per metre of drop differs from the axis's), so the drop is
    stepped by at most half a block of the axis's run, and over each step the bundle lies within that much of the
    axis's segment, no lower than the lowest origin less the step's end."""
    if not grid.holds_all:
        return False
    c = first
    cx, cy = np.float64(origins[c, 0]), np.float64(origins[c, 1])
    z_low, z_high, r0, g = np.inf, -np.inf, 0.0, 0.0
    gcx, gcy = 0.0, 0.0
    for j in range(m):
        k = first + j
        dz = np.float64(dirs[k, 2])
        if not dz < 0.0:
            return False
        gx, gy = np.float64(dirs[k, 0]) / -dz, np.float64(dirs[k, 1]) / -dz
        if j == 0:
            gcx, gcy = gx, gy
        oz = np.float64(origins[k, 2])
        z_low, z_high = min(z_low, oz), max(z_high, oz)
        r0 = max(r0, (np.float64(origins[k, 0]) - cx) ** 2 + (np.float64(origins[k, 1]) - cy) ** 2)
        g = max(g, (gx - gcx) ** 2 + (gy - gcy) ** 2)
    r0, g = math.sqrt(r0), math.sqrt(g)
    depth = z_high - grid.z_bottom + CLEARANCE_M  # every ray is below all geometry once it has dropped this far
    size = grid.super_k * grid.k * grid.spacing
    run = math.sqrt(gcx * gcx + gcy * gcy)
    step = min(MISS_STEP_BLOCKS * size, 0.5 * size / run) if run > 0.0 else MISS_STEP_BLOCKS * size
    sy, sx = grid.super_top.shape
    x_end, y_end = grid.x0 + sx * size, grid.y0 + sy * size
    h0 = 0.0
    while h0 < depth:
        h1 = min(h0 + step, depth)
        r = r0 + h1 * g + CLEARANCE_M
        x_lo, x_hi = cx + min(h0 * gcx, h1 * gcx) - r, cx + max(h0 * gcx, h1 * gcx) + r
        y_lo, y_hi = cy + min(h0 * gcy, h1 * gcy) - r, cy + max(h0 * gcy, h1 * gcy) + r
        # Past an edge of the blocks and drawing away from it faster than it widens: nothing further on.
        if ((x_lo > x_end and gcx >= g) or (x_hi < grid.x0 and -gcx >= g) or (y_lo > y_end and gcy >= g)
                or (y_hi < grid.y0 and -gcy >= g)):
            return True
        j0, j1 = max(0, math.floor((x_lo - grid.x0) / size)), min(sx - 1, math.floor((x_hi - grid.x0) / size))
        i0, i1 = max(0, math.floor((y_lo - grid.y0) / size)), min(sy - 1, math.floor((y_hi - grid.y0) / size))
        low = z_low - h1 - CLEARANCE_M  # the lowest any ray can be over this step
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                if grid.super_top[i, j] >= low:
                    return False
        h0 = h1
    return True


@kernel(inline="always")
def _segment_rows(segments):
    """The rows of a (7, k) scratch of segments for :func:`_bundle_clear`: their seabed points' x, y and z, their end
    heights, their horizontal directions' x and y and their rises."""
    return segments[0], segments[1], segments[2], segments[3], segments[4], segments[5], segments[6]


@kernel(nogil=True, error_model="numpy")
def analytic_block(origins, dirs, axis_prim, axis_tfar, p0, rx_local, grid, shadow, prim, tfar, analytic, segments):
    """The ``auto`` level's analytic sub-ray hits on the seabed, for one block of pulses.

    origins, dirs ((n m, 3) float32, pulse-major): the block's sub-rays, sub-ray 0 the beam axis; axis_prim,
    axis_tfar (n,): Embree's first hit of each axis. Writes Embree's answer for the axis into ``prim``/``tfar``
    ((n m,), as Embree's raw output) and, for each pulse it can prove the others of, their hits too, with
    ``analytic[q]`` True; other pulses' other sub-rays are left to Embree (``analytic[q]`` False). A pulse whose axis
    met nothing is proven, its other sub-rays' ``prim`` -1, where :func:`_bundle_misses` proves none can meet anything.

    A pulse is proven when its axis hits the seabed and each sub-ray, followed down the height field's triangles
    (the plane of one, then the triangle under that point, until they agree), lands on a seabed triangle; and
    no sub-ray can have met anything before that: over every coarse cell the bundle crosses below the top of the
    scene, no other object reaches up to it, and the seabed either stays below it or slopes less than the
    steepest sub-ray descends, so that a sub-ray crosses the seabed once only (:func:`_bundle_clear`). With
    ``shadow`` the segments from the hits to the receiver aperture (``rx_local[p0 + q]``) must pass the same test
    rising: then no shadow ray of the pulse can be blocked, and none is cast. ``segments`` (7, 2 m): the caller's
    scratch; every argument is borrowed (:mod:`muls.infra.borrowed`)."""
    origins, dirs, axis_prim, axis_tfar, rx_local, grid, prim, tfar, analytic, segments = borrowed(
        (origins, dirs, axis_prim, axis_tfar, rx_local, grid, prim, tfar, analytic, segments))
    n = axis_prim.shape[0]
    m = origins.shape[0] // n
    plane, face0, cell_face = grid.plane, grid.face0, grid.cell_face
    gaps = cell_face.shape[0] > 0
    x0, y0, spacing, nx, ny = grid.x0, grid.y0, grid.spacing, grid.nx, grid.ny
    # Segments to test: the m sub-rays back up from their hits, then (shadow) the m hits up to the receiver.
    hx, hy, hz, z_end, wx, wy, rise = _segment_rows(segments)
    for q in range(n):
        f0 = axis_prim[q]
        prim[q * m] = f0
        tfar[q * m] = axis_tfar[q]
        if f0 < 0:  # the axis met nothing: proven when nothing can meet any sub-ray either
            analytic[q] = _bundle_misses(grid, origins, dirs, q * m, m)
            if analytic[q]:
                prim[q * m + 1:(q + 1) * m] = -1
            continue
        ok = face0 <= f0 < face0 + plane.shape[0]
        for j in range(m):
            if not ok:
                break
            k = q * m + j
            ox, oy, oz = np.float64(origins[k, 0]), np.float64(origins[k, 1]), np.float64(origins[k, 2])
            dx, dy, dz = np.float64(dirs[k, 0]), np.float64(dirs[k, 1]), np.float64(dirs[k, 2])
            if not dz < 0.0:
                ok = False
                break
            if j == 0:
                t = np.float64(axis_tfar[q])
            else:
                # Follow the height field: the plane of face f, then the face under that point, until they agree.
                f, found, t = (f0 if j == 1 else prim[k - 1]) - face0, False, 0.0
                for _ in range(8):
                    t = (plane[f, 3] - (plane[f, 0] * ox + plane[f, 1] * oy + plane[f, 2] * oz)) / (
                        plane[f, 0] * dx + plane[f, 1] * dy + plane[f, 2] * dz)
                    g = seabed_face_at(x0, y0, spacing, nx, ny, ox + t * dx, oy + t * dy) if t > 0.0 else -1
                    if g >= 0 and gaps:
                        g = cell_face[g]
                    if g < 0:  # off the height field, or over a gap: the sub-ray may meet something further on
                        break
                    if g == f:
                        found = True
                        break
                    f = g
                if not found:
                    ok = False
                    break
                t32 = np.float32(t)
                prim[k] = f + face0
                tfar[k] = t32
                t = np.float64(t32)
            hx[j], hy[j], hz[j] = ox + t * dx, oy + t * dy, oz + t * dz
            h2 = dx * dx + dy * dy  # back up the ray, away from its hit: rising -dz / h per metre
            if h2 > 0.0:
                inv_h = 1.0 / math.sqrt(h2)
                rise[j], wx[j], wy[j] = -dz * inv_h, -dx * inv_h, -dy * inv_h
            else:
                rise[j], wx[j], wy[j] = np.inf, 0.0, 0.0
            z_end[j] = oz
        if ok:
            fx, fy = hx[0], hy[0]
            reach2, zmin = 0.0, np.inf  # the farthest hit's squared distance: one square root (it is monotone)
            for j in range(m):
                reach2 = max(reach2, (hx[j] - fx) ** 2 + (hy[j] - fy) ** 2)
                zmin = min(zmin, hz[j])
            reach = math.sqrt(reach2)
            segments = m
            if shadow:  # one test for both bundles: they leave the footprint for nearly the same place
                rx, ry, rz = rx_local[p0 + q, 0], rx_local[p0 + q, 1], rx_local[p0 + q, 2]
                for j in range(m):
                    above, rise_j, wx_j, wy_j = _rising_toward(hx[j], hy[j], hz[j], rx, ry, rz)
                    if not above:
                        ok = False
                        break
                    s = m + j
                    hx[s], hy[s], hz[s], z_end[s], rise[s], wx[s], wy[s] = hx[j], hy[j], hz[j], rz, rise_j, wx_j, wy_j
                segments = 2 * m
            if ok:
                ok = _bundle_clear(grid, hx, hy, hz, z_end, wx, wy, rise, segments, fx, fy, reach, zmin)
        analytic[q] = ok


@kernel(nogil=True)
def unproven_shadows(pulse, p0, analytic, length):
    """Indices of the shadow rays to cast: those not empty (length > 0) of hit rows whose pulse (``pulse`` - p0)
    :func:`analytic_block` did not prove."""
    out = np.empty(pulse.shape[0], np.int64)
    k = 0
    for c in range(pulse.shape[0]):
        if length[c] > 0.0 and not analytic[pulse[c] - p0]:
            out[k] = c
            k += 1
    return out[:k]


@kernel(nogil=True, error_model="numpy")
def shadows_to_cast(grid, rows, local_origin, rx_local, sh_len, first, count, need, segments, rows_of):
    """Which of a block's shadow rays Embree must cast: writes their indices (0 .. ``count`` - 1, for hit rows
    ``first`` ..) into ``need`` and returns how many.

    rows: :class:`scanner_sim.rays.hits.HitColumns` in scan order, ``m`` sub-rays per pulse at most; sh_len (count,):
    each row's shadow-ray length (<= 0: empty, never cast); rx_local (n_pulses, 3): the receiver apertures in the
    local frame (``local_origin`` [m] off the world frame); ``segments`` (7, m) float and ``rows_of`` (m,) int64: the
    caller's scratch (every argument is borrowed, :mod:`muls.infra.borrowed`). A pulse's non-empty shadow rays are
    all left out when every one of them starts on the seabed (``grid.object_id``) and :func:`_bundle_clear` proves
    that nothing can meet the straight segments from those hits up to the aperture: then Embree would find none
    blocked. A hit on anything else, or a test that fails, casts them all."""
    grid, rows, local_origin, rx_local, sh_len, need, segments, rows_of = borrowed(
        (grid, rows, local_origin, rx_local, sh_len, need, segments, rows_of))
    hx, hy, hz, z_end, wx, wy, rise = _segment_rows(segments)
    pulse, point = rows.pulse_index, rows.point
    k, c = 0, 0
    while c < count:
        p = pulse[first + c]
        n, proven = 0, True
        while c < count and pulse[first + c] == p:
            if sh_len[c] > 0.0:
                rows_of[n] = c
                n += 1
                proven = proven and rows.object_id[first + c] == grid.object_id
            c += 1
        if n == 0:
            continue
        if proven:
            rx, ry, rz = rx_local[p, 0], rx_local[p, 1], rx_local[p, 2]
            fx, fy = point[first + rows_of[0], 0] - local_origin[0], point[first + rows_of[0], 1] - local_origin[1]
            reach, zmin = 0.0, np.inf
            for j in range(n):
                i = first + rows_of[j]
                x, y, z = point[i, 0] - local_origin[0], point[i, 1] - local_origin[1], point[i, 2] - local_origin[2]
                above, rise_j, wx_j, wy_j = _rising_toward(x, y, z, rx, ry, rz)
                if not above:
                    proven = False
                    break
                hx[j], hy[j], hz[j], z_end[j], rise[j], wx[j], wy[j] = x, y, z, rz, rise_j, wx_j, wy_j
                reach = max(reach, math.sqrt((x - fx) ** 2 + (y - fy) ** 2))
                zmin = min(zmin, z)
            proven = proven and _bundle_clear(grid, hx, hy, hz, z_end, wx, wy, rise, n, fx, fy, reach, zmin)
        if not proven:
            for j in range(n):
                need[k] = rows_of[j]
                k += 1
    return k
