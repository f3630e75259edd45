"""The optical model's values at a sample, compiled: the filtered pulse (MULS Eq. 2), the water column's integrals
and power uncut or cut at a range, the baseline, and the stepped pulse recurrence (:func:`add_pulse_steps`) that the
digitiser's CH0 reference, the peak search's echo model and the ranging's span terms share. They take the model's
arrays (:class:`~muls.optics.optical_model.ColumnKernel` as ``col``, the pulse basis) and return numbers or fill
arrays; :class:`~muls.optics.optical_model.OpticalModel` builds those arrays."""

from __future__ import annotations

import math

import numpy as np

from ..infra.runtime import kernel


@kernel(inline="always")
def pulse_value(u, basis):
    """Filtered unit-area pulse at u seconds after its start [1/s] (MULS Eq. 2 through the bandwidth)."""
    if u < 0.0:
        return 0.0
    return (basis[2] * u + basis[3]) * math.exp(-basis[0] * u) + basis[4] * math.exp(-basis[1] * u)


@kernel(inline="always")
def column_integrals_at(tau, col):
    """(S0a, S1a, S0b) of the module doc at two-way time tau [s], interpolated in the tables; zeros past them."""
    table = col.integrals
    x = tau / col.step_s
    i = int(x)
    if i >= table.shape[0] - 1:
        return 0.0, 0.0, 0.0
    f = x - i
    return (table[i, 0] + f * (table[i + 1, 0] - table[i, 0]), table[i, 1] + f * (table[i + 1, 1] - table[i, 1]),
            table[i, 2] + f * (table[i + 1, 2] - table[i, 2]))


@kernel(inline="always")
def uncut_column_value(t, col):
    """Power [W] at time t [s] of the column of a beam that meets nothing (:func:`column_value` with no cut): one
    interpolation in ``col.uncut`` instead of three and their combination."""
    if t <= 0.0:
        return 0.0
    x = t / col.step_s
    i = int(x)
    if i >= col.uncut.shape[0] - 1:
        return 0.0
    return col.uncut[i] + (x - i) * (col.uncut[i + 1] - col.uncut[i])


@kernel(nogil=True, error_model="numpy")
def baseline_values(out, times, background_w, col):
    """out[k] = ``background_w`` + :func:`uncut_column_value` (times[k]) [W], the same numbers, in a loop whose
    branches are selects (the table index clamped), so it runs on SIMD lanes."""
    table, last = col.uncut, col.uncut.shape[0] - 1
    for k in range(times.shape[0]):
        x = times[k] / col.step_s
        i = int(min(max(x, 0.0), last - 1.0))
        inside = (times[k] > 0.0) & (x < last)
        out[k] = background_w + (table[i] + (x - i) * (table[i + 1] - table[i]) if inside else 0.0)


@kernel(inline="always")
def column_value(t, cut_tau, col):
    """Column power [W] at time t [s] of a beam cut at two-way time cut_tau [s] (exact cut, see module doc);
    ``col`` a :class:`ColumnKernel`."""
    if t <= 0.0:
        return 0.0
    basis = col.basis
    tau = t if t < cut_tau else cut_tau
    v0a, v1a, v0b = column_integrals_at(tau, col)
    if t < cut_tau:  # before the cut's echo: the full column, u = 0
        return basis[2] * v1a + basis[3] * v0a + basis[4] * v0b
    u = t - tau
    ea = math.exp(-basis[0] * u)
    return (basis[2] * (u * v0a + v1a) + basis[3] * v0a) * ea + basis[4] * v0b * math.exp(-basis[1] * u)


@kernel(nogil=True)
def _column_many(t, cut_tau, col):
    out = np.empty(t.shape[0])
    for i in range(t.shape[0]):
        out[i] = column_value(t[i], cut_tau[i], col)
    return out


@kernel
def cut_column_power(t, p, col, cuts):
    """Power [W] at time t [s] of batch pulse p's column as its targets cut it, plus background (MULS Eq. 1 less
    the echoes, which :func:`add_pulse_steps` adds)."""
    power = cuts.background_w[p]
    for c in range(cuts.cut_tau_s.shape[1]):
        if cuts.cut_weight[p, c] != 0.0:
            power += cuts.cut_weight[p, c] * column_value(t, cuts.cut_tau_s[p, c], col)
    return power


@kernel(inline="always")
def add_pulse_steps(out, first, u, dt, scale, extent, basis, exact_u):
    """out[j] += scale * :func:`pulse_value` (u_j) for j = first, first + 1, ... while u_j < ``extent`` [s] (an
    echo's term of MULS Eq. 1 on samples ``dt`` [s] apart), the pulse basis's two exponentials stepped from sample
    to sample by constant factors: four exps in all. u_j [s]: ``exact_u[j]`` where ``exact_u`` (len(out),) is
    given (not empty), else ``u`` at ``first`` plus ``dt`` a step. u_first must be >= 0."""
    if exact_u.shape[0] > 0:
        u = exact_u[first]
    ea, eb = math.exp(-basis[0] * u), math.exp(-basis[1] * u)
    ra, rb = math.exp(-basis[0] * dt), math.exp(-basis[1] * dt)
    for j in range(first, out.shape[0]):
        if exact_u.shape[0] > 0:
            u = exact_u[j]
        if u >= extent:
            return
        out[j] += scale * ((basis[2] * u + basis[3]) * ea + basis[4] * eb)
        u += dt
        ea *= ra
        eb *= rb
