"""The settings the compiled kernels share, packed as float arrays with named positions.

``geo`` holds the transceiver geometry and the variance-reduction settings (positions below; numba reads
the position names as compile-time constants); ``water`` = (a, b, c, group speed); ``times`` =
(histogram step, histogram length, grid step, grid length, end of the run). The target planes travel as
the tuple ``scene`` = (normal n towards the instrument, in-plane axes e1, e2, penetration depth of each
plane (K,), receiver-grid origins (K, 3), ring edges (K, n_r + 1), grid start times (K,), azimuth sectors,
reflectance) and the phase function as ``phase`` = (sampling table, ln p table, ln theta of its first
point, 1 / its step).
"""

from __future__ import annotations

import math

import numpy as np

# Positions in ``geo``.
(BEAM_RADIUS, BEAM_SLOPE, APERTURE_X, APERTURE_RADIUS, FOV_TAN, FOV_COS, FOV_HALF, CONE_APERTURES, CONE_MAX,
 GHOSTS_ON, MIX_P, MIX_WIDE, WIDE_RAD, SURVIVAL, CONE_FOV, CONE_APERTURE, GHOST_LENGTH, SPLIT_MAX,
 SPLIT_REACH) = range(19)
GEO_SIZE = 19


def geo_vector(beam_diameter_m: float, beam_divergence_full_rad: float, offset_m: float, aperture_radius_m: float,
               fov_full_rad: float, devices: dict) -> np.ndarray:
    """(GEO_SIZE,) the transceiver geometry and the variance-reduction ``devices`` (keys as in transport)."""
    half = 0.5 * fov_full_rad
    geo = np.zeros(GEO_SIZE)
    geo[BEAM_RADIUS] = 0.5 * beam_diameter_m
    geo[BEAM_SLOPE] = math.tan(0.5 * beam_divergence_full_rad)
    geo[APERTURE_X] = offset_m
    geo[APERTURE_RADIUS] = aperture_radius_m
    geo[FOV_TAN] = math.tan(half)
    geo[FOV_COS] = math.cos(half)
    geo[FOV_HALF] = half
    geo[CONE_APERTURES] = devices["cone_apertures"]
    geo[CONE_MAX] = devices["cone_max_rad"]
    geo[GHOSTS_ON] = 1.0 if devices["ghosts"] else 0.0
    geo[MIX_P] = devices["ghost_mix"]
    geo[MIX_WIDE] = devices["ghost_wide_share"]
    geo[WIDE_RAD] = devices["ghost_wide_rad"]
    geo[SURVIVAL] = devices["ghost_survival"]
    geo[CONE_FOV] = devices["ghost_cone_fov"]
    geo[CONE_APERTURE] = devices["ghost_cone_aperture"]
    geo[GHOST_LENGTH] = devices["ghost_length_m"]
    geo[SPLIT_MAX] = devices["split_max"]
    geo[SPLIT_REACH] = devices["split_reach_m"]
    return geo
