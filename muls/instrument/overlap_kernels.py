"""The compiled kernels of the transceiver overlap (:mod:`muls.instrument.overlap` has the geometry and the models):
the lens area of two discs, the share of a finite aperture that sees a point, and the finite-aperture overlap over
ranges. Apart from the geometry so that describing an instrument compiles nothing."""

from __future__ import annotations

import math

import numpy as np

from ..infra.runtime import kernel


@kernel(inline="always")
def lens_area(r1, r2, s):
    """Area [m^2] of the intersection of two discs of radii ``r1``, ``r2`` [m] whose centres are ``s`` [m] apart."""
    if s >= r1 + r2:
        return 0.0
    small = min(r1, r2)
    if s <= abs(r1 - r2):
        return math.pi * small * small
    c1 = min(1.0, max(-1.0, (s * s + r1 * r1 - r2 * r2) / (2.0 * s * r1)))
    c2 = min(1.0, max(-1.0, (s * s + r2 * r2 - r1 * r1) / (2.0 * s * r2)))
    k = (-s + r1 + r2) * (s + r1 - r2) * (s - r1 + r2) * (s + r1 + r2)
    return r1 * r1 * math.acos(c1) + r2 * r2 * math.acos(c2) - 0.5 * math.sqrt(max(k, 0.0))


@kernel(inline="always")
def aperture_share(aperture_radius_m, tan_half_fov, along_m, across_m):
    """Share [-] of a circular aperture whose own field of view holds a point ``along_m`` [m] in front of the
    aperture along the receiver axis and ``across_m`` [m] from that axis (0 behind the aperture)."""
    if along_m <= 0.0:
        return 0.0
    return lens_area(aperture_radius_m, along_m * tan_half_fov, across_m) / (math.pi * aperture_radius_m**2)


@kernel(nogil=True)
def finite_aperture_overlap(z, r0_beam, tan_beam, r_ap, tan_fov, d, nodes, weights):
    """The finite-aperture overlap at ranges ``z`` (n,) [m]: the aperture share averaged over the spot, as an
    integral over the distance s from the receiver axis (Gauss-Legendre ``nodes``, ``weights`` on [-1, 1], on each
    piece between the integrand's kinks)."""
    out = np.zeros(z.shape[0])
    breaks = np.empty(6)
    for i in range(z.shape[0]):
        if z[i] <= 0.0:
            continue
        r1 = r0_beam + z[i] * tan_beam
        rho = z[i] * tan_fov
        lo, hi = max(0.0, d - r1), d + r1
        # Kinks of the integrand in s: the spot's edge (|d - r1|, d + r1) and the lens's (|r_ap - rho|, r_ap + rho).
        breaks[0], breaks[1], breaks[2], breaks[3], breaks[4], breaks[5] = (lo, abs(d - r1), abs(r_ap - rho),
                                                                           r_ap + rho, hi, hi)
        for j in range(1, 6):  # in ascending order (an insertion sort: numba's sort costs a second to compile)
            v, m = breaks[j], j
            while m > 0 and breaks[m - 1] > v:
                breaks[m] = breaks[m - 1]
                m -= 1
            breaks[m] = v
        total = 0.0
        for j in range(5):
            a, b = max(lo, breaks[j]), min(hi, breaks[j + 1])
            if b <= a:
                continue
            for k in range(nodes.shape[0]):
                s = 0.5 * (b - a) * nodes[k] + 0.5 * (b + a)
                if s <= 0.0:
                    continue
                # Share of the circle of radius s around the receiver axis inside the spot (arc / 2 pi s).
                if d == 0.0 or s + d <= r1:
                    arc = math.pi if s < r1 or d > 0.0 else 0.0
                else:
                    arc = math.acos(min(1.0, max(-1.0, (s * s + d * d - r1 * r1) / (2.0 * s * d))))
                density = 2.0 * s * arc / (math.pi * r1 * r1)  # of s, for a uniform spot
                total += 0.5 * (b - a) * weights[k] * density * lens_area(r_ap, rho, s)
        out[i] = total / (math.pi * r_ap * r_ap)
    return out
