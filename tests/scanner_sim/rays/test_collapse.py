"""The ``auto`` level's collapse of a simple footprint's sub-ray echoes to two (scanner_sim.rays.collapse): its stated
bound, checked on the echo itself, the instrument's pulse summed over the sub-ray delays against the two-point
rule's two pulses."""

import numpy as np
import pytest

from muls.presets import mul2023
from scanner_sim.rays.beams import beam_pattern
from scanner_sim.rays.cast import kernel_inputs
from scanner_sim.rays.caster import RayCaster
from scanner_sim.rays.collapse import COLLAPSE_SPAN_M, cast_pulse_figures, pulse_figures, two_point_rule
from scanner_sim.rays.hits import empty_columns
from scanner_sim.rays.kernels import ShadowRays, hit_block, subrays_local32
from scanner_sim.world.objects import panel_mesh
from scanner_sim.world.scene import LABELS, Part, Scene

#: [m/s] Light in sea water (n = 1.34): an echo range r is a delay 2 r / V.
V = 2.998e8 / 1.34
SUBRAYS = 19


def _echoes(energy, delay, pulse, t):
    """The received power shape: the pulse at each delay, weighted by its energy, summed (n_times,)."""
    return np.sum(energy[:, None] * pulse(t[None, :] - delay[:, None]), axis=0)


@pytest.mark.parametrize("layout", ["even", "random", "three_lumps"])
def test_a_footprint_spread_up_to_the_collapse_span_gives_the_echo_of_its_sub_rays(layout):
    """Nineteen sub-ray echoes spread over COLLAPSE_SPAN_M of range, through the instrument's 200 MHz bandwidth:
    the two-point rule's two echoes differ from their sum by under 0.5 % of its peak anywhere, and put its peak
    within 0.5 mm of range. That is far under the noise of any echo the ranging accepts (SNR 3 or more: 33 % of
    the peak), so the ranged point moves less than the bound the docs state (fidelity.md, auto)."""
    pulse = mul2023().pulse
    rng = np.random.default_rng({"even": 1, "random": 2, "three_lumps": 3}[layout])
    t = np.arange(-5e-9, 60e-9, 2e-12)
    for _ in range(20):
        if layout == "even":
            r = np.linspace(0.0, COLLAPSE_SPAN_M, SUBRAYS)
        elif layout == "random":
            r = np.r_[0.0, COLLAPSE_SPAN_M, rng.uniform(0.0, COLLAPSE_SPAN_M, SUBRAYS - 2)]
        else:  # the footprint in three lumps, at both ends of the span and its middle (a two-point rule is exact
            # for two lumps, not for three)
            r = COLLAPSE_SPAN_M * (np.arange(SUBRAYS) % 3) / 2.0
        energy = rng.uniform(0.2, 1.0, SUBRAYS)
        delay = 2.0 * r / V
        full = _echoes(energy, delay, pulse, t)
        nodes, share = two_point_rule(energy[None], delay[None])
        two = _echoes(energy.sum() * share[0], nodes[0], pulse, t)
        assert np.abs(two - full).max() < 5e-3 * full.max()
        assert abs(t[two.argmax()] - t[full.argmax()]) * V / 2.0 < 5e-4


def test_the_bound_grows_past_the_span_so_wider_footprints_keep_their_sub_ray_echoes():
    """At four times COLLAPSE_SPAN_M, ranges spread evenly, the two-point echo is off by more than the bound: the
    span is where the collapse stops being exact enough, not an arbitrary cut (such footprints keep one echo per
    sub-ray, test_auto_level)."""
    pulse = mul2023().pulse
    t = np.arange(-5e-9, 60e-9, 2e-12)
    r = np.linspace(0.0, 4 * COLLAPSE_SPAN_M, SUBRAYS)
    energy, delay = np.ones(SUBRAYS), 2.0 * r / V
    full = _echoes(energy, delay, pulse, t)
    nodes, share = two_point_rule(energy[None], delay[None])
    two = _echoes(energy.sum() * share[0], nodes[0], pulse, t)
    assert np.abs(two - full).max() > 5e-3 * full.max()


def test_a_cast_pulses_figures_are_those_of_its_hit_rows_to_the_bit():
    """cast_pulse_figures sums a pulse's collapse figures straight from its cast, without the 19 hit rows, by
    hit_block's arithmetic: on footprints on a tilted plane (simple) and over a plate's edge (two surfaces, kept),
    its beam share, reflectance, cosine, mean range, nodes and shares are those pulse_figures gives from
    hit_block's rows, bit for bit."""
    plane = panel_mesh([0.0, 0.0, -3.0], (8.0, 8.0), (0.3, 0.1, 1.0), (0, 1, 0))
    plate = panel_mesh([0.3, 0.2, -2.4], (0.5, 0.5), (0, 0, 1), (0, 1, 0))
    scene = Scene([Part("floor", "seabed", *plane, LABELS["seabed"], 0.2),
                   Part("plate", "panel", *plate, LABELS["panel"], 0.6)])
    rng = np.random.default_rng(4)
    n, pattern, geometry = 600, beam_pattern(SUBRAYS), mul2023().geometry
    tilt, azimuth = np.radians(75.0) * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    direction = np.c_[np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)]
    origin = np.c_[rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n)]
    edge = slice(0, n // 2)  # half straight down onto the plate's edge x = 0.55 m, within their 1-2 cm footprint
    direction[edge] = [0.0, 0.0, -1.0]
    origin[edge, 0] = 0.55 + rng.uniform(-0.008, 0.008, n // 2)
    rays, layout, faces, view = kernel_inputs(scene, origin, direction, np.tile([1.0, 0.0, 0.0], (n, 1)),
                                              origin + [0.0, geometry.offset_m, 0.0], direction, pattern, geometry)
    caster = RayCaster.for_scene(scene)
    o32, d32 = np.empty((n * SUBRAYS, 3), np.float32), np.empty((n * SUBRAYS, 3), np.float32)
    subrays_local32(rays, 0, n, layout, o32, d32)
    prim, tfar = caster.first_hits_raw(o32, d32)
    rows, shadows = empty_columns(SUBRAYS), ShadowRays(*(np.empty((SUBRAYS, 3), np.float32) for _ in range(2)),
                                                       np.empty(SUBRAYS, np.float32))
    scratch = [np.empty(SUBRAYS), np.empty(SUBRAYS), np.empty(2), np.empty(2)]
    kinds = []
    for q in range(n):
        at = slice(q * SUBRAYS, (q + 1) * SUBRAYS)
        if np.any(prim[at] < 0):
            continue
        c = hit_block(prim[at], tfar[at], q * SUBRAYS, 0, rays, layout, faces, view, rows, shadows)
        expected = pulse_figures(0, c, SUBRAYS, rows, False, *scratch)
        nodes, share = scratch[2].copy(), scratch[3].copy()
        got = cast_pulse_figures(prim[at], tfar[at], q, rays, layout, faces, view, *scratch)
        assert got == expected, q
        if expected[0] > 0:
            np.testing.assert_array_equal(scratch[2], nodes)
            np.testing.assert_array_equal(scratch[3], share)
        kinds.append("simple" if expected[0] > 0 else "kept")
    assert kinds.count("simple") > 100 and kinds.count("kept") > 50, (kinds.count("simple"), kinds.count("kept"))
