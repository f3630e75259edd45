"""Beam footprint sampling: sub-rays over the beam's cross-section and their energy weights.

A beam of exit radius r_t [m] and half divergence theta_h [rad] has, at range z along its axis, the spot
radius r1(z) = r_t + z tan(theta_h) (MULS Eq. 11's r1). A sub-ray at normalised position (x, y) in the unit
disc starts at ``r_t (x u + y v)`` from the beam origin and points along ``a + tan(theta_h) (x u + y v)``
(normalised), where ``a`` is the beam axis and ``u, v`` an orthonormal pair across it. At axial distance z it
is therefore exactly at ``r1(z) (x, y)``: the sub-rays fill the spot the way Eq. 11 assumes at every range.

Layout: concentric rings, ring n (n = 1..N) holding 6 n points, so the counts are 1, 7, 19, 37, 61, 91, ...
(1 + 3 N (N + 1)). Every point stands for an equal-area cell: ring n covers the annulus between radii
a_{n-1} and a_n with a_n^2 = (1 + 3 n (n + 1)) / (1 + 3 N (N + 1)) (the centre point the disc of radius a_0),
and its points sit on the radius that halves that annulus' area. Each ring is turned by a small stagger
(:data:`RING_STAGGER_RAD`) so that no two rings line up: a straight edge crossing the spot (the receiver footprint's edge, in
the overlap test) then uncovers points one at a time instead of whole rows at once, which is what makes the
ray-cast overlap converge to Eq. 11 (tests/scanner_sim/rays/test_beams.py, test_geometry_overlap.py).

Weights sum to 1. ``top_hat``: each point gets its cell's share of a uniform disc (equal weights, the profile
Eq. 11 assumes). ``gaussian``: each point gets its cell's integral of exp(-2 rho^2 / w^2) over the unit disc,
with w = ``gaussian_waist`` (1 = the 1/e^2 radius at the spot edge), renormalised over the disc.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config.sections import PROFILES, SUBRAY_COUNTS

#: Rotation of ring n relative to ring n - 1 [rad]. Chosen by minimising the worst ray-cast overlap error against
#: Eq. 11 over 1-8 m for the mul2023 geometry (edge of the footprint across the shaft direction u): 1.5 degrees
#: gives 0.021 at 61 sub-rays and 0.014 at 91; the golden angle gives 0.032 and 0.018, no stagger 0.08.
RING_STAGGER_RAD = math.radians(1.5)


@dataclass(frozen=True)
class BeamPattern:
    """Sub-ray layout in the unit disc. ``xy`` (m, 2) float64 normalised positions, ``weight`` (m,) summing to 1,
    ``ring`` (m,) int32 ring number (0 = centre)."""

    xy: np.ndarray
    weight: np.ndarray
    ring: np.ndarray
    profile: str

    @property
    def count(self) -> int:
        return int(self.weight.shape[0])

    @property
    def rho(self) -> np.ndarray:
        """(m,) normalised radial position of each sub-ray."""
        return np.hypot(self.xy[:, 0], self.xy[:, 1])


def beam_pattern(count: int, profile: str = "top_hat", gaussian_waist: float = 1.0) -> BeamPattern:
    """Ring layout of ``count`` sub-rays (one of :data:`SUBRAY_COUNTS`) with weights summing to 1; sub-ray 0
    is the beam axis (the coverage footprint reads the axis hit from it)."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or int(count) not in SUBRAY_COUNTS:
        raise ParameterError(f"subrays = {count!r}: must be one of {', '.join(map(str, SUBRAY_COUNTS))}")
    if profile not in PROFILES:
        raise ParameterError(f"beam_profile = {profile!r}: must be one of {', '.join(map(repr, PROFILES))}")
    if not (gaussian_waist > 0.0 and math.isfinite(gaussian_waist)):
        raise ParameterError(f"gaussian_waist = {gaussian_waist!r}: must be > 0")
    n_rings = SUBRAY_COUNTS.index(int(count))
    cumulative = np.array([1 + 3 * n * (n + 1) for n in range(n_rings + 1)], float)
    edge_sq = cumulative / cumulative[-1]  # a_n^2: equal-area cell boundaries
    xy, ring, inner_sq, outer_sq = [np.zeros((1, 2))], [np.zeros(1, np.int32)], [0.0], [edge_sq[0]]
    for n in range(1, n_rings + 1):
        radius = math.sqrt(0.5 * (edge_sq[n - 1] + edge_sq[n]))  # halves the annulus' area
        phi = 2.0 * np.pi * np.arange(6 * n) / (6 * n) + n * RING_STAGGER_RAD
        xy.append(radius * np.c_[np.cos(phi), np.sin(phi)])
        ring.append(np.full(6 * n, n, np.int32))
        inner_sq += [edge_sq[n - 1]] * (6 * n)
        outer_sq += [edge_sq[n]] * (6 * n)
    xy = np.concatenate(xy)
    ring = np.concatenate(ring)
    inner_sq, outer_sq = np.array(inner_sq), np.array(outer_sq)
    per_ring = np.bincount(ring).astype(float)[ring]
    if profile == "top_hat":
        weight = (outer_sq - inner_sq) / per_ring  # area share of each cell of a uniform disc
    else:
        k = 2.0 / gaussian_waist**2  # intensity exp(-2 rho^2 / w^2); its integral over an annulus is closed-form
        weight = (np.exp(-k * inner_sq) - np.exp(-k * outer_sq)) / per_ring
    weight = weight / weight.sum()
    return BeamPattern(xy=xy, weight=weight, ring=ring, profile=profile)


def perpendicular_basis(axis: np.ndarray, hint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal ``u, v`` (n, 3) across unit ``axis`` (n, 3); ``u`` is ``hint`` (n, 3) made perpendicular.

    The scanner passes the mirror shaft as the hint, so ``u`` lies along the transmitter-receiver offset.
    """
    u = hint - np.sum(hint * axis, axis=1, keepdims=True) * axis
    norm = np.linalg.norm(u, axis=1, keepdims=True)
    bad = norm[:, 0] < 1e-9
    if np.any(bad):  # hint parallel to the axis: any perpendicular will do
        alt = np.where(np.abs(axis[bad, 0:1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        u[bad] = alt - np.sum(alt * axis[bad], axis=1, keepdims=True) * axis[bad]
        norm[bad] = np.linalg.norm(u[bad], axis=1, keepdims=True)
    u = u / norm
    v = np.cross(axis, u)
    return u, v


def subrays(beam_origin: np.ndarray, beam_dir: np.ndarray, shaft_dir: np.ndarray, pattern: BeamPattern,
            beam_radius_m: float, half_divergence_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """World-frame sub-rays of a batch of beams, pulse-major (scan order).

    beam_origin, beam_dir, shaft_dir: (n, 3) float64 (directions unit); beam_radius_m: r_t [m] at the exit;
    half_divergence_rad: theta_h [rad]. Returns origins (n * m, 3) float64 and unit directions (n * m, 3) float64;
    row ``p * m + j`` is sub-ray j of pulse p. The spot radius at axial range z is r_t + z tan(theta_h), MULS
    Eq. 11's r1.
    """
    n, m = beam_origin.shape[0], pattern.count
    u, v = perpendicular_basis(beam_dir, shaft_dir)
    x, y = pattern.xy[:, 0], pattern.xy[:, 1]
    across = x[None, :, None] * u[:, None, :] + y[None, :, None] * v[:, None, :]  # (n, m, 3)
    origins = beam_origin[:, None, :] + beam_radius_m * across
    dirs = beam_dir[:, None, :] + math.tan(half_divergence_rad) * across
    dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
    return origins.reshape(n * m, 3), dirs.reshape(n * m, 3)
