"""The ``auto`` level's collapse of a simple footprint's sub-ray echoes to two (scanner_sim.rays.collapse): its stated
bound, checked on the echo itself, the instrument's pulse summed over the sub-ray delays against the two-point
rule's two pulses."""

import numpy as np
import pytest

from muls.presets import mul2023
from scanner_sim.rays.collapse import COLLAPSE_SPAN_M, two_point_rule

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
