"""A study's sample of a pass: stretches of consecutive pulses spread evenly over it (scanner_sim/survey/pass_sample.py,
PassSetup.spread_sample)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from scanner_sim.config import load_scene
from scanner_sim.studies.tradeoff import sampled_pass
from scanner_sim.survey.pass_sample import spread_stretches


@pytest.mark.parametrize("n, pulses, count", [(300, 30, 3), (1000, 999, 4), (5, 4, 3), (7, 6, 3), (10, 3, 8),
                                              (1_000_000, 30_000, 3)])
def test_the_stretches_hold_the_pulses_asked_in_order_without_overlap(n, pulses, count):
    stretches = spread_stretches(n, pulses, count)
    assert sum(size for _, size in stretches) == pulses
    assert len(stretches) == min(count, pulses)
    ends = [0] + [first + size for first, size in stretches]
    assert all(first >= end for (first, _), end in zip(stretches, ends))  # each after the one before
    assert ends[-1] <= n
    sizes = [size for _, size in stretches]
    assert max(sizes) - min(sizes) <= 1


def test_each_stretch_lies_about_the_middle_of_its_share_of_the_pass():
    """300 pulses in three shares of 100: 10 pulses about each share's middle (50, 150, 250)."""
    assert spread_stretches(300, 30, 3) == [(45, 10), (145, 10), (245, 10)]
    assert spread_stretches(300, 10, 1) == [(145, 10)]


def test_a_sample_as_large_as_the_pass_is_the_pass():
    assert spread_stretches(300, 300, 3) == [(0, 300)]
    assert spread_stretches(300, 500, 3) == [(0, 300)]
    assert spread_stretches(0, 10, 3) == []


def test_the_sampled_pass_runs_runs_of_consecutive_pulses_of_the_whole_pass():
    """cable_survey cut to 3,000 pulses in chunks of 1,000: three stretches, each 1,000 consecutive fired pulses of the
    whole pass (its slots in the same order), one in each third of the pass, as the trade-off runs them."""
    config = load_scene("cable_survey").with_overrides({"survey.chunk_pulses": 1000})
    sample = sampled_pass(config, 3000)
    whole = np.concatenate(list(dataclasses.replace(sample, stretches=()).slot_chunks()))
    chunks = list(sample.slot_chunks())
    assert sample.expected_pulses() == 3000 == sum(c.size for c in chunks)
    assert len(sample.stretches) == 3
    for i, (first, end) in enumerate(sample.stretches):
        slots = np.concatenate([c for c in chunks if first <= c[0] < end])
        at = int(np.searchsorted(whole, slots[0]))
        assert np.array_equal(whole[at:at + slots.size], slots)  # consecutive pulses of the pass
        assert i * whole.size // 3 <= at and at + slots.size <= (i + 1) * whole.size // 3


def test_a_pass_no_longer_than_the_sample_is_run_whole():
    """A failure scene fires 2,000 pulses (its survey.max_pulses): a 3,000-pulse trade-off runs them all, from the
    first, as the scenes' geometry assumes (docs/assumptions.md)."""
    sample = sampled_pass(load_scene(str(Path(__file__).parents[3] / "scenes/failures/step_edges.yaml")), 3000)
    assert sample.stretches == () and sample.expected_pulses() == 2000
