"""The emitted pulse shape (MULS Eq. 2, n = 1) and its image through the analog bandwidth.

The pulse is normalised to unit area [1/s], so E_t * w(t) is the emitted power [W]. The digitiser's analog
bandwidth B is a first-order low-pass (time constant 1 / (2 pi B)); every signal of the model is the pulse
convolved with something, so the filter is applied once, to the pulse, in closed form:

    w_B(t) = (A t + B0) exp(-a t) + C exp(-b t),   a = k / dt, b = 2 pi B, t >= 0

This exponential basis is also what lets the water column be cut at any range exactly (see ``column``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..infra.errors import check_positive

#: k of Eq. 2 for n = 1 that makes the width parameter the full width at half maximum: the two roots of
#: x exp(1 - x) = 1/2 are k apart.
PULSE_SHAPE_K = 2.446386


@dataclass(frozen=True)
class PulseShape:
    """Unit-area pulse of FWHM ``width_s`` [s], optionally low-passed at ``bandwidth_hz`` [Hz]."""

    width_s: float
    bandwidth_hz: float | None = None

    def __post_init__(self):
        check_positive("pulse_width_s", self.width_s)
        if self.bandwidth_hz is not None:
            check_positive("bandwidth_hz", self.bandwidth_hz)

    @property
    def decay_per_s(self) -> float:
        """a = k / dt [1/s]."""
        return PULSE_SHAPE_K / self.width_s

    @property
    def rms_width_s(self) -> float:
        """Standard deviation [s] of the pulse's time profile: sqrt(2) / a for Eq. 2 (n = 1, a gamma density of
        shape 2), and a low-pass of time constant 1 / b adds its variance 1 / b^2 (a convolution's variances add)."""
        var = 2.0 / self.decay_per_s**2
        if self.bandwidth_hz is not None:
            var += 1.0 / (2.0 * math.pi * self.bandwidth_hz) ** 2
        return math.sqrt(var)

    def basis(self) -> tuple[float, float, float, float, float]:
        """(a, b, A, B0, C) with w(t) = (A t + B0) exp(-a t) + C exp(-b t) for t >= 0, in SI units."""
        a = self.decay_per_s
        if self.bandwidth_hz is None:
            return a, a, a * a, 0.0, 0.0  # MULS Eq. 2, n = 1, unit area: a^2 t exp(-a t)
        b = 2.0 * math.pi * self.bandwidth_hz
        d = b - a
        if abs(d) < 1e-6 * b:
            raise ValueError("bandwidth_hz makes the filter pole coincide with the pulse decay; change it slightly")
        # Eq. 2 convolved with b exp(-b t): a^2 b exp(-b t) * integral_0^t s exp(d s) ds.
        return a, b, a * a * b / d, -a * a * b / (d * d), a * a * b / (d * d)

    def __call__(self, t_s):
        """Pulse power density w(t) [1/s] at times ``t_s`` [s] after emission (any shape)."""
        t = np.asarray(t_s, dtype=float)
        a, b, A, B0, C = self.basis()
        tp = np.maximum(t, 0.0)
        value = (A * tp + B0) * np.exp(-a * tp) + C * np.exp(-b * tp)
        return np.where(t >= 0.0, value, 0.0)

    @cached_property
    def peak_delay_s(self) -> float:
        """Time of the maximum after emission [s] (0.409 dt unfiltered; later with the filter); a bisection,
        computed once per shape."""
        a, b, A, B0, C = self.basis()
        if C == 0.0:
            return 1.0 / a
        # d w / dt = exp(-a t)(A - a (A t + B0)) - b C exp(-b t): solve by bisection on [0, 10 / a].
        lo, hi = 0.0, 10.0 / a
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            slope = math.exp(-a * mid) * (A - a * (A * mid + B0)) - b * C * math.exp(-b * mid)
            lo, hi = (mid, hi) if slope > 0 else (lo, mid)
        return 0.5 * (lo + hi)

    @cached_property
    def peak_per_s(self) -> float:
        """The pulse's maximum [1/s], at :attr:`peak_delay_s` (the pulse rises to it and falls after it)."""
        return float(self(self.peak_delay_s))

    @cached_property
    def fall_to_half_s(self) -> float:
        """[s] Time from the maximum to half of it on the falling side (6.9 ns for the mul2023 pulse)."""
        peak = self.peak_delay_s
        top = self.peak_per_s
        lo, hi = peak, self.duration_s
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if float(self(mid)) > 0.5 * top else (lo, mid)
        return 0.5 * (lo + hi) - peak

    @property
    def duration_s(self) -> float:
        """Time after which the unfiltered pulse is below 1.1e-7 of its peak [s] (the extent synthesis keeps)."""
        return 20.0 / self.decay_per_s
