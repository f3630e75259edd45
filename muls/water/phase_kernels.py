"""The compiled helpers of the phase functions (:mod:`muls.water.phase` has the functions and their tables): the
kernels of :mod:`muls.montecarlo` call these with a phase function's tables. Apart from the tables so that describing
a water compiles nothing."""

from __future__ import annotations

import math

from ..infra.lookup import bracket
from ..infra.runtime import kernel


@kernel(inline="always")
def sample_angle(sample_theta, u):
    """Scattering angle [rad] whose cumulative probability is ``u`` in [0, 1) (inverse CDF, linear)."""
    x = u * (sample_theta.shape[0] - 1)
    i = int(x)
    return sample_theta[i] + (x - i) * (sample_theta[i + 1] - sample_theta[i])


@kernel
def cumulative_at(sample_theta, theta):
    """Probability of a scattering angle below ``theta`` [rad]: the exact inverse of :func:`sample_angle`.

    ``sample_angle(sample_theta, u * cumulative_at(sample_theta, theta))`` for u uniform in [0, 1) draws
    an angle from p restricted to angles below theta.
    """
    m = sample_theta.shape[0] - 1
    if theta >= sample_theta[m]:
        return 1.0
    if theta <= sample_theta[0]:
        return 0.0
    lo = bracket(theta, sample_theta)
    return (lo + (theta - sample_theta[lo]) / (sample_theta[lo + 1] - sample_theta[lo])) / m


@kernel(inline="always")
def value_at(ln_p, ln_theta0, inv_step, theta):
    """p(theta) [1/sr] from the ln p table (linear in ln theta; clamped to the grid's ends)."""
    if theta <= 0.0:
        return math.exp(ln_p[0])
    x = (math.log(theta) - ln_theta0) * inv_step
    if x <= 0.0:
        return math.exp(ln_p[0])
    i = int(x)
    if i >= ln_p.shape[0] - 1:
        return math.exp(ln_p[-1])
    f = x - i
    return math.exp(ln_p[i] + f * (ln_p[i + 1] - ln_p[i]))
