"""What a hit sends back to the receiver: the formulas of the hand-off from hits to MULS echoes, used by the
pass's hand-off (:mod:`scanner_sim.survey.handoff`) and by the ``auto`` level's collapsed echoes
(:mod:`scanner_sim.rays.collapse`) alike.

The functions are compiled and take scalars (inside kernels) or arrays (from numpy code).
"""

from __future__ import annotations

from muls.infra.runtime import kernel

#: [m] Sub-ray echoes closer than this in range count as one place: they share one water-column cut
#: (survey.handoff.column_cuts). Under half the 0.11 m of range one 1 ns sample spans and a twentieth of the 10 ns
#: pulse's 1.1 m; measured on cable_survey, the per-sub-ray cut costs nothing over one cut per pulse at this bin.
#: (The ``auto`` level collapses a footprint's echoes to two within its own span, rays.collapse.COLLAPSE_SPAN_M.)
ECHO_BIN_M = 0.05


@kernel(nogil=True)
def echo_range_m(range_m, return_leg_m):
    """[m] The range that times a hit's echo (its delay is 2 x this / c_w): half the path laser -> hit (``range_m``
    along the sub-ray) -> receiver aperture (``return_leg_m``)."""
    return 0.5 * (range_m + return_leg_m)


@kernel(nogil=True)
def echo_energy(weight, reflectance, cos_incidence, receiver_weight):
    """The energy a sub-ray's echo brings back, up to the factors every echo of a pulse shares (MULS Eq. 7 per
    sub-ray without E_t A_r eta (1 - T_s)^2 exp(-2 k R) / (pi R^2)): its share of the beam ``weight`` x Lambertian
    ``reflectance`` x ``cos_incidence`` x ``receiver_weight`` (1 when the receiver sees the hit, else 0)."""
    return weight * reflectance * cos_incidence * receiver_weight
