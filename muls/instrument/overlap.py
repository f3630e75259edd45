"""Transceiver geometry: the overlap of beam and receiver, as MULS Eq. 11 gives it and as a finite aperture sees it.

Beam and receiver axes are parallel, ``offset_m`` apart. At range z the beam spot has radius
r1 = d_t / 2 + z tan(theta_t / 2) and the receiver footprint r2 = d_r / 2 + z tan(theta_r / 2), with the
full angles theta_t (divergence) and theta_r (field of view).

- ``eq11`` (MULS Eq. 11): the area of the two discs' intersection over the beam spot's area. It counts the whole
  aperture for every point inside the union of the aperture points' fields of view.
- ``finite_aperture`` (the default): each aperture point sees only what lies within its own field of view, a disc
  of radius rho = z tan(theta_r / 2) around its own axis. A point of the spot at distance s from the receiver
  axis is seen by the share lens(r_ap, rho, s) / (pi r_ap^2) of the aperture
  (:func:`~muls.instrument.overlap_kernels.lens_area`: the intersection of the aperture disc and the disc of radius
  rho around the point), and the overlap is that share averaged over the uniformly lit spot. It is 0 up to
  (d - r1 - r_ap) / tan(theta_r / 2) and reaches Eq. 11's plateau only where every aperture point sees the
  whole spot, about 3.6 m for the MUL instead of Eq. 11's 2.0 m. The Monte Carlo reference (:mod:`muls.montecarlo`)
  sees the same geometry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..infra.errors import ParameterError, check_non_negative, check_positive

#: How the receiver's view of the beam is modelled: each aperture point's own field (default), or MULS Eq. 11.
OVERLAP_MODELS = ("finite_aperture", "eq11")
#: Points of the quadrature over the distance from the receiver axis in :meth:`TransceiverGeometry.overlap`'s
#: finite-aperture integral (split at the integrand's kinks; 1e-5 of the plateau, checked in the tests).
OVERLAP_QUADRATURE_POINTS = 64


@dataclass(frozen=True)
class TransceiverGeometry:
    """Beam and receiver geometry. All lengths [m], angles full angles [rad]."""

    beam_diameter_m: float
    beam_divergence_full_rad: float
    receiver_diameter_m: float
    fov_full_rad: float
    offset_m: float
    overlap_model: str = "finite_aperture"

    def __post_init__(self):
        if self.overlap_model not in OVERLAP_MODELS:
            raise ParameterError(f"overlap_model = {self.overlap_model!r}: must be one of "
                                 f"{', '.join(map(repr, OVERLAP_MODELS))}")
        check_positive("beam_diameter_m", self.beam_diameter_m)
        check_non_negative("beam_divergence_full_rad", self.beam_divergence_full_rad)
        check_positive("receiver_diameter_m", self.receiver_diameter_m)
        check_positive("fov_full_rad", self.fov_full_rad)
        check_non_negative("offset_m", self.offset_m)
        if self.fov_full_rad >= math.pi or self.beam_divergence_full_rad >= math.pi:
            raise ValueError("fov_full_rad and beam_divergence_full_rad must be < pi (full angles in radians)")

    @property
    def receiver_area_m2(self) -> float:
        return math.pi * (0.5 * self.receiver_diameter_m) ** 2

    def beam_radius_m(self, z_m):
        """r1(z) [m]: beam spot radius at range z."""
        return 0.5 * self.beam_diameter_m + np.asarray(z_m, float) * math.tan(0.5 * self.beam_divergence_full_rad)

    def footprint_radius_m(self, z_m):
        """r2(z) [m]: receiver footprint radius at range z."""
        return 0.5 * self.receiver_diameter_m + np.asarray(z_m, float) * math.tan(0.5 * self.fov_full_rad)

    @property
    def blind_zone_m(self) -> float:
        """Z1 [m]: the range below which beam and footprint do not touch (overlap 0)."""
        r10, r20 = 0.5 * self.beam_diameter_m, 0.5 * self.receiver_diameter_m
        t1, t2 = math.tan(0.5 * self.beam_divergence_full_rad), math.tan(0.5 * self.fov_full_rad)
        return max(0.0, (self.offset_m - r10 - r20) / (t1 + t2))

    @property
    def full_overlap_m(self) -> float:
        """Z2 [m]: the range from which the overlap is 1: under Eq. 11 where the beam spot lies wholly inside the
        footprint; with a finite aperture where every aperture point's own field holds the whole spot.

        ``inf`` when the beam spreads at least as fast as the field of view and never fits inside it.
        """
        r10, r20 = 0.5 * self.beam_diameter_m, 0.5 * self.receiver_diameter_m
        t1, t2 = math.tan(0.5 * self.beam_divergence_full_rad), math.tan(0.5 * self.fov_full_rad)
        if self.overlap_model != "eq11":
            return (self.offset_m + r20 + r10) / (t2 - t1) if t2 > t1 else math.inf
        gap = self.offset_m - (r20 - r10)
        if gap <= 0.0:
            return 0.0
        return gap / (t2 - t1) if t2 > t1 else math.inf

    @property
    def aperture_radius_m(self) -> float:
        return 0.5 * self.receiver_diameter_m

    def overlap(self, z_m):
        """O(z) [-] of the geometry's ``overlap_model`` for ranges ``z_m`` [m] (any shape); 0 for z <= 0."""
        if self.overlap_model == "eq11":
            return self.eq11_overlap(z_m)
        return self.finite_aperture_overlap(z_m)

    def finite_aperture_overlap(self, z_m):
        """O(z) [-] with each aperture point seeing its own field of view (module doc) at ``z_m`` [m] (any shape)."""
        from .overlap_kernels import finite_aperture_overlap  # numba: here, so that describing an instrument needs none

        z = np.asarray(z_m, dtype=float)
        nodes, weights = np.polynomial.legendre.leggauss(OVERLAP_QUADRATURE_POINTS)
        flat = finite_aperture_overlap(np.ascontiguousarray(z.ravel()), 0.5 * self.beam_diameter_m,
                                        math.tan(0.5 * self.beam_divergence_full_rad), self.aperture_radius_m,
                                        math.tan(0.5 * self.fov_full_rad), float(self.offset_m), nodes, weights)
        return np.clip(flat, 0.0, 1.0).reshape(z.shape)

    def eq11_overlap(self, z_m):
        """O(z) of MULS Eq. 11 for ranges ``z_m`` [m] (any shape); 0 for z <= 0."""
        z = np.asarray(z_m, dtype=float)
        r1 = self.beam_radius_m(np.maximum(z, 0.0))
        r2 = self.footprint_radius_m(np.maximum(z, 0.0))
        d = self.offset_m
        contained = d <= np.abs(r2 - r1)
        apart = d >= r1 + r2
        with np.errstate(invalid="ignore", divide="ignore"):
            # Overlap sector angles by the law of cosines (paper, below Eq. 11).
            w1 = 2.0 * np.arccos(np.clip((d * d + r1 * r1 - r2 * r2) / (2.0 * d * r1), -1.0, 1.0))
            w2 = 2.0 * np.arccos(np.clip((d * d + r2 * r2 - r1 * r1) / (2.0 * d * r2), -1.0, 1.0))
            lens = ((w1 - np.sin(w1)) * r1**2 + (w2 - np.sin(w2)) * r2**2) / (2.0 * np.pi * r1**2)  # MULS Eq. 11
        inside = np.minimum(r1, r2) ** 2 / r1**2  # one disc inside the other
        result = np.where(apart, 0.0, np.where(contained, inside, lens))
        return np.where(z > 0.0, np.clip(result, 0.0, 1.0), 0.0)

    def collection_limit(self, z_m):
        """Field-stop limit on the collecting area that Eq. 11 leaves out, min(1, pi (z tan(theta_r/2))^2 / A_r) [-]
        (1 under the finite-aperture overlap, which holds it already).

        A scatterer on the beam at range z is seen only by the part of the aperture whose field of view
        contains it, a disc of radius z tan(theta_r / 2). Far away this is the whole aperture (factor 1);
        close in it keeps A_r O(z) / z^2 finite, which matters only for a coaxial design whose Eq. 11
        overlap is 1 down to the window.
        """
        z = np.maximum(np.asarray(z_m, dtype=float), 0.0)
        if self.overlap_model != "eq11":
            return np.ones(z.shape)
        seen = math.pi * (z * math.tan(0.5 * self.fov_full_rad)) ** 2
        return np.minimum(1.0, seen / self.receiver_area_m2)
