"""Lookup tables of the known pulse shape that ranging inverts: the three-point peak fit and the width of a
clipped plateau. They depend only on the pulse and the sample interval, so a model builds them once."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .pulse import PulseShape


class FitTable(NamedTuple):
    """Three-point fit to the known pulse shape, by the parabolic feature (ascending).

    For samples y(-1), y(0), y(1) around a maximum, the feature (y1 - y-1) / (2 (2 y0 - y-1 - y1)) is a
    monotone function of the true peak's offset from sample 0 for the (asymmetric) pulse; inverting it
    removes the phase-dependent bias of parabolic and Gaussian fits. feature (k,); offset (k,) [samples];
    centre (k,): the middle sample over the peak.
    """

    feature: np.ndarray
    offset: np.ndarray
    centre: np.ndarray

    @classmethod
    def build(cls, pulse: PulseShape, sample_interval_s: float) -> FitTable:
        dt = sample_interval_s
        offset = np.linspace(-0.5, 0.5, 1001)

        def shape(u):
            return pulse(u + pulse.peak_delay_s) / pulse.peak_per_s

        before, centre, after = shape((-1.0 - offset) * dt), shape(-offset * dt), shape((1.0 - offset) * dt)
        feature = (after - before) / (2.0 * (2.0 * centre - before - after))
        return cls(feature, offset, centre)


class ClipTable(NamedTuple):
    """For a pulse cut at ``ratio`` of its peak (600 levels on a geometric grid from 1e-9 to 1): how long
    before its peak it rises through that level (``rise``) and how long after it falls through it
    (``fall``), both in samples."""

    ratio: np.ndarray
    rise: np.ndarray
    fall: np.ndarray

    @classmethod
    def build(cls, pulse: PulseShape, sample_interval_s: float) -> ClipTable:
        dt = sample_interval_s
        u = np.linspace(0.0, 2.0 * pulse.duration_s, 80001)
        f = pulse(u) / pulse.peak_per_s
        i_peak = int(np.argmax(f))
        ratio = np.geomspace(1e-9, 1.0, 600)
        rising = np.interp(ratio, f[: i_peak + 1], u[: i_peak + 1])
        falling = np.interp(ratio, f[i_peak:][::-1], u[i_peak:][::-1])
        return cls(ratio, (u[i_peak] - rising) / dt, (falling - u[i_peak]) / dt)
