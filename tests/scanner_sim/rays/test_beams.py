"""Beam sub-ray layout: counts, weights, spot radius, and convergence of the ray-cast overlap to the analytic one,
under each overlap model (a finite aperture, each point with its own field of view; MULS Eq. 11)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from muls.presets import mul2023
from scanner_sim.rays.beams import SUBRAY_COUNTS, beam_pattern, subrays
from scanner_sim.studies.raycast_overlap import raycast_overlap

GEOMETRY = mul2023().geometry
GEOMETRIES = {model: replace(GEOMETRY, overlap_model=model) for model in ("finite_aperture", "eq11")}
OVERLAP_TOLERANCE = 0.03  # ray-cast overlap within 0.03 of the analytic one with >= 61 sub-rays


@pytest.mark.parametrize("count", SUBRAY_COUNTS[:7])
@pytest.mark.parametrize("profile", ["top_hat", "gaussian"])
def test_weights_sum_to_one(count, profile):
    p = beam_pattern(count, profile)
    assert p.count == count
    assert p.weight.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(p.weight > 0)
    assert np.all(p.rho <= 1.0)
    # ring n holds 6 n points
    assert np.array_equal(np.bincount(p.ring)[1:], 6 * np.arange(1, len(np.bincount(p.ring))))
    assert np.array_equal(p.xy[0], [0.0, 0.0])  # sub-ray 0 is the axis: the coverage footprint relies on it


def test_top_hat_is_equal_area_and_gaussian_peaks_in_the_centre():
    top = beam_pattern(61)
    assert np.allclose(top.weight, 1 / 61)
    gauss = beam_pattern(61, "gaussian")
    assert gauss.weight[0] > gauss.weight[-1] * 3


@pytest.mark.parametrize("bad", [0, 5, 62, 7.5, "61", True])
def test_bad_count_names_allowed_values(bad):
    with pytest.raises(ValueError, match="subrays.*1, 7, 19, 37, 61, 91"):
        beam_pattern(bad)


def test_outer_subrays_trace_the_spot_radius_r1():
    """A sub-ray at rho = 1 is at r1(z) = r_t + z tan(theta/2) from the axis at every axial range z."""
    p = beam_pattern(19)
    o, d = subrays(np.zeros((1, 3)), np.array([[0, 0, -1.0]]), np.array([[1.0, 0, 0]]), p,
                   0.5 * GEOMETRY.beam_diameter_m, 0.5 * GEOMETRY.beam_divergence_full_rad)
    for z in (0.5, 3.0, 10.0):
        t = z / -d[:, 2]
        lateral = np.hypot(*(o + t[:, None] * d)[:, :2].T)
        np.testing.assert_allclose(lateral, p.rho * GEOMETRY.beam_radius_m(z), rtol=1e-12, atol=1e-15)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)


@pytest.mark.parametrize("model", GEOMETRIES)
def test_overlap_within_tolerance_at_acceptance_distances(model):
    geometry = GEOMETRIES[model]
    d = np.array([1, 1.5, 2, 2.5, 3, 4, 5, 6, 7, 8.0])
    for count in (61, 91):
        err = np.abs(raycast_overlap(d, geometry, count) - geometry.overlap(d))
        assert err.max() <= OVERLAP_TOLERANCE, (count, err)


@pytest.mark.parametrize("model", GEOMETRIES)
def test_overlap_error_shrinks_as_subrays_grow(model):
    """Worst error over the partial-overlap zone (Z1 1.68 m to Z2: 3.59 m with a finite aperture, 2.03 m under
    Eq. 11), densely sampled, falls with every step in sub-ray count, and is inside the tolerance from 61 on."""
    geometry = GEOMETRIES[model]
    d = np.linspace(geometry.blind_zone_m - 0.02, geometry.full_overlap_m + 0.05, 41)
    worst = []
    for count in (7, 19, 37, 61, 91):
        worst.append(np.abs(raycast_overlap(d, geometry, count, shadow_rays=False) - geometry.overlap(d)).max())
    assert all(a > b for a, b in zip(worst, worst[1:])), worst
    assert worst[3] <= OVERLAP_TOLERANCE and worst[4] <= OVERLAP_TOLERANCE, worst
    assert worst[0] > 2 * worst[4]


def test_overlap_converges_far_from_the_origin():
    d = np.array([1.5, 1.8, 1.9, 2.0, 3.0, 4.0])
    here = raycast_overlap(d, GEOMETRY, 61)
    utm = raycast_overlap(d, GEOMETRY, 61, origin_m=(512345.6, 6123456.7, -40.0))
    np.testing.assert_allclose(utm, here, rtol=0, atol=1e-8)  # float32 hit points: a share moves by 1e-9 at most
    assert math.isclose(float(here[-1]), 1.0)
