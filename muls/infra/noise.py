"""Counter-based random numbers: each draw is a pure function of (seed, pulse id, stream, sample index).

Why not a sequential generator: the windowed and full-record modes synthesise different subsets of samples,
and a pass is cut into chunks of any size; both must see the same noise at the same sample. A counter-based
stream (SplitMix64 finaliser over a Weyl sequence, the generator of Steele et al. 2014) gives that for free
and costs a few integer operations per draw inside the numba kernels.
"""

from __future__ import annotations

import math

import numpy as np

from .runtime import kernel

#: Weyl increment of the SplitMix64 sequence (the golden ratio in 64 bits).
GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_INV_2_32 = 1.0 / 4294967296.0

#: Stream numbers: the sampling phase, the CH0 noise, then one stream per pair of signal channels for their
#: dark noise (the two normals of one draw serve channels 2j and 2j + 1), then one stream per pair of
#: detectors for their shot noise (channels of one detector share its draw; muls.receiver.digitiser).
PHASE_STREAM = 0
REFERENCE_STREAM = 1
FIRST_SIGNAL_STREAM = 2


def seed_key(seed) -> np.uint64:
    """64-bit key of a run from an int seed or a ``numpy.random.Generator`` (which is advanced once)."""
    if isinstance(seed, np.random.Generator):
        seed = int(seed.integers(0, 2**63))
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed = {seed!r}: must be a non-negative integer or a numpy.random.Generator")
    return np.uint64(splitmix64(np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF)))


@kernel(inline="always")
def splitmix64(z):
    """The SplitMix64 finaliser: a 64-bit integer to a well-mixed one (Steele et al. 2014)."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@kernel(inline="always")
def stream_base(key, pulse_id, stream):
    """State of one (pulse, stream) sequence."""
    return splitmix64(key ^ splitmix64(np.uint64(pulse_id) * np.uint64(64) + np.uint64(stream) + GAMMA))


@kernel(inline="always")
def hash_at(base, index):
    """The 64 bits of position ``index`` of a stream: two 32-bit halves, two normals (:func:`normal_of_bits`)."""
    return splitmix64(base + (np.uint64(index) + np.uint64(1)) * GAMMA)


@kernel(inline="always")
def uniform_at(base, index):
    """Uniform in [0, 1) at position ``index`` of a stream."""
    h = hash_at(base, index)
    return float(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


# Acklam's rational approximation of the inverse normal CDF (relative error < 1.2e-9): a polynomial ratio in
# the central 95 % of draws, sqrt(log) only in the tails; far cheaper than Box-Muller's log, sqrt, sin, cos.
_A = (-3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02, 1.383577518672690e02,
      -3.066479806614716e01, 2.506628277459239e00)
_B = (-5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02, 6.680131188771972e01,
      -1.328068155288572e01)
_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00, -2.549732539343734e00,
      4.374664141464968e00, 2.938163982698783e00)
_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00, 3.754408661907416e00)
_P_LOW = 0.02425
#: Every normal drawn here is smaller than this in magnitude: the inverse CDF of the outermost cell centre,
#: 0.5 / 2^32, is -6.3380 (:func:`centred_unit`), so a sample whose noise-free code lies further from a bound of
#: the digitiser's range than this many sigma has a known code without a draw.
NORMAL_BOUND = 6.34


@kernel(inline="always")
def _central_normal(p):
    """Acklam's central rational, for p in [_P_LOW, 1 - _P_LOW] (no branch, so a loop of these vectorises)."""
    q = p - 0.5
    r = q * q
    return ((((( _A[0] * r + _A[1]) * r + _A[2]) * r + _A[3]) * r + _A[4]) * r + _A[5]) * q / (
        ((((_B[0] * r + _B[1]) * r + _B[2]) * r + _B[3]) * r + _B[4]) * r + 1.0)


@kernel(inline="always")
def _in_tail(p):
    return p < _P_LOW or p > 1.0 - _P_LOW


@kernel(inline="always")
def _tail_normal(p):
    """Acklam's tail formula, for p outside [_P_LOW, 1 - _P_LOW]."""
    q = math.sqrt(-2.0 * math.log(p if p < 0.5 else 1.0 - p))
    x = ((((( _C[0] * q + _C[1]) * q + _C[2]) * q + _C[3]) * q + _C[4]) * q + _C[5]) / (
        (((_D[0] * q + _D[1]) * q + _D[2]) * q + _D[3]) * q + 1.0)
    return x if p < 0.5 else -x


@kernel(inline="always")
def _inverse_normal_cdf(p):
    return _tail_normal(p) if _in_tail(p) else _central_normal(p)


@kernel(inline="always")
def centred_unit(bits32):
    """A 32-bit integer k to (k + 1/2) / 2^32: the centres of 2^32 equal cells of (0, 1), never 0 or 1 and
    symmetric about 1/2 (k and 2^32 - 1 - k give p and 1 - p), so the normals are finite and symmetric."""
    # Through a signed int32 shifted by 2^31 (exact: every step is an integer below 2^53): the same value as
    # float(uint32) + 0.5, but a conversion SIMD lanes have, where an unsigned one is emulated.
    return (float(np.int32(np.int64(bits32) - 2147483648)) + 2147483648.5) * _INV_2_32


@kernel(inline="always")
def half_bits(h, half):
    """32-bit half ``half`` (0: the high bits, 1: the low) of a position's hash ``h``."""
    return h >> np.uint64(32) if half == 0 else h & np.uint64(0xFFFFFFFF)


@kernel(inline="always")
def normal_of_bits(bits32):
    """The standard normal of a 32-bit half, |x| < :data:`NORMAL_BOUND`."""
    return _inverse_normal_cdf(centred_unit(bits32))


@kernel(inline="always")
def normal_half_at(base, index, half):
    """The standard normal of 32-bit half ``half`` (0: the high bits, 1: the low) of position ``index`` of a stream:
    each position gives two independent normals, |x| < :data:`NORMAL_BOUND`."""
    return normal_of_bits(half_bits(hash_at(base, index), half))


@kernel(nogil=True)
def fill_hashes(base, first_index, out):
    """out[k] = :func:`hash_at` (base, first_index + k), k < out.shape[0] (uint64)."""
    base = np.uint64(base)
    for k in range(out.shape[0]):
        out[k] = hash_at(base, first_index + k)


@kernel(inline="always")
def _list_flagged(flags, listed):
    """The indices k of the nonzero ``flags[k]`` into ``listed``, in order, without a branch; returns how many. A
    loop that branched on each flag instead mispredicts at random (one draw in twenty lies in a tail), which cost the
    tails' patch more than their logarithms."""
    m = 0
    for k in range(flags.shape[0]):
        listed[m] = k
        m += flags[k] != 0
    return m


@kernel(nogil=True, error_model="numpy")
def fill_normals_of(hashes, half, at, out, tails):
    """out[i] = :func:`normal_of_bits` (:func:`half_bits` (hashes[at[i]], half)) for i < at.shape[0], bit for bit;
    ``tails`` (2 m,) int64 scratch. As :func:`fill_normal_pairs`: a loop without a branch for the central formula,
    then the draws in the tails listed and patched."""
    m = at.shape[0]
    in_tail, listed = tails[m:2 * m], tails[:m]
    for i in range(m):
        p = centred_unit(half_bits(hashes[at[i]], half))
        out[i] = _central_normal(p)
        in_tail[i] = np.int64(_in_tail(p))
    for i in range(_list_flagged(in_tail, listed)):
        j = listed[i]
        out[j] = _tail_normal(centred_unit(half_bits(hashes[at[j]], half)))


#: :func:`normal_upper_bound` reads a table of the top 12 bits of a half: 4,096 cells of 2^20 values each.
UPPER_BOUND_SHIFT = np.uint64(20)


def _upper_bounds() -> np.ndarray:
    """(4096,) the normal of each cell's last value, plus 1e-6: more than the inverse CDF's approximation can wiggle
    (its relative error is 1.2e-9, |x| < 6.34) or numpy's sums differ from the kernels' in their last bits, so each
    value bounds every normal of its cell from above (the approximation rises with its argument). Acklam's formulas of
    :func:`_inverse_normal_cdf` on numpy arrays, not a kernel: a first run that never reads the bound (only full
    records' read samples do) compiles nothing for it."""
    cells = 1 << (32 - int(UPPER_BOUND_SHIFT))
    last_of_cell = (np.arange(1, cells + 1, dtype=np.float64) * float(1 << int(UPPER_BOUND_SHIFT))) - 1.0
    p = (last_of_cell + 0.5) * _INV_2_32  # centred_unit's value, exact in float64
    q = p - 0.5
    r = q * q
    central = (((((_A[0] * r + _A[1]) * r + _A[2]) * r + _A[3]) * r + _A[4]) * r + _A[5]) * q / (
        ((((_B[0] * r + _B[1]) * r + _B[2]) * r + _B[3]) * r + _B[4]) * r + 1.0)
    t = np.sqrt(-2.0 * np.log(np.minimum(p, 1.0 - p)))
    tail = (((((_C[0] * t + _C[1]) * t + _C[2]) * t + _C[3]) * t + _C[4]) * t + _C[5]) / (
        (((_D[0] * t + _D[1]) * t + _D[2]) * t + _D[3]) * t + 1.0)
    in_tail = (p < _P_LOW) | (p > 1.0 - _P_LOW)
    return np.where(in_tail, np.where(p < 0.5, tail, -tail), central) + 1e-6


# Built at import, as a global: numba freezes a global array into the kernels that read it, which then know it aliases
# none of their outputs and keep the bound's loop on SIMD lanes (passed as an argument, the same table cost the
# full-record digitiser 2 us a pulse more). In numpy, 0.1 ms: the kernels' own values to the bit.
_NORMAL_UPPER = _upper_bounds()


@kernel(inline="always")
def normal_upper_bound(bits32):
    """A number at least :func:`normal_of_bits` (bits32), at most 0.015 above it where |x| < 2.5 (a table lookup, no
    division or log): enough to tell that a draw cannot exceed a level without drawing it."""
    return _NORMAL_UPPER[bits32 >> UPPER_BOUND_SHIFT]


@kernel(inline="always")
def normal_bounds(bits32):
    """(lower, upper) bounds of :func:`normal_of_bits` (bits32) from :func:`normal_upper_bound`'s table, without
    drawing: the normals are antisymmetric (:func:`centred_unit` gives the complement 2^32 - 1 - bits32 the value
    1 - p, whose normal is -x to the bit), so the lower bound is the complement's upper bound, negated."""
    return -normal_upper_bound(np.uint64(0xFFFFFFFF) - bits32), normal_upper_bound(bits32)


@kernel(inline="always")
def dark_noise_stream(c):
    """(stream, half) of signal channel ``c``'s dark noise: half c % 2 of its pair's stream (:data:`FIRST_SIGNAL_STREAM`)."""
    return FIRST_SIGNAL_STREAM + c // 2, c % 2


@kernel(inline="always")
def shot_noise_stream(d, n_channels):
    """(stream, half) of detector ``d``'s shot noise, after the dark-noise streams of ``n_channels`` signal channels."""
    return FIRST_SIGNAL_STREAM + (n_channels + 1) // 2 + d // 2, d % 2


@kernel(inline="always")
def normal_at(base, index):
    """Standard normal at position ``index`` of a stream (its first half)."""
    return normal_half_at(base, index, 0)


@kernel(nogil=True, error_model="numpy")
def fill_normal_pairs(base, first_index, high, low, tails):
    """The normals of both halves of positions ``first_index + k`` of a stream, ``k < high.shape[0]``: ``high[k]``,
    ``low[k]`` equal :func:`normal_half_at` (..., 0) and (..., 1) bit for bit; an empty ``low`` (shape (0,)) skips the
    second half. ``tails``: (2 n,) int64 scratch.

    A block at once costs about two thirds of draw by draw: the first loop has no branch (the central formula
    everywhere; numpy's error model drops the division's zero check), so it runs on SIMD lanes; then the positions
    with a draw in a tail (one in ten) are listed (:func:`_list_flagged`) and patched, hashing them again. The first
    loop comes in two copies, with and without the low half: one loop that tests for it inside kept a high half alone
    30 % slower. A listed position's two halves are both taken through the tail formula and the one in no tail left
    as it was (a select, not a branch: which half it is falls at random).
    """
    n, base = high.shape[0], np.uint64(base)  # a Python int would make numba mix int64 and uint64 into float64
    both = low.shape[0] > 0
    in_tail, listed = tails[n:2 * n], tails[:n]  # bit 0: the high half's draw in a tail, bit 1: the low half's
    if both:
        for k in range(n):
            h = hash_at(base, first_index + k)
            p_high, p_low = centred_unit(half_bits(h, 0)), centred_unit(half_bits(h, 1))
            high[k], low[k] = _central_normal(p_high), _central_normal(p_low)
            in_tail[k] = np.int64(_in_tail(p_high)) | (np.int64(_in_tail(p_low)) << 1)
    else:
        for k in range(n):
            p_high = centred_unit(half_bits(hash_at(base, first_index + k), 0))
            high[k] = _central_normal(p_high)
            in_tail[k] = np.int64(_in_tail(p_high))
    for i in range(_list_flagged(in_tail, listed)):
        k = listed[i]
        h = hash_at(base, first_index + k)
        x = _tail_normal(centred_unit(half_bits(h, 0)))
        high[k] = x if in_tail[k] & 1 else high[k]
        if both:
            x = _tail_normal(centred_unit(half_bits(h, 1)))
            low[k] = x if in_tail[k] & 2 else low[k]


@kernel
def _normals(key, pulse_id, stream, index):
    out = np.empty(index.shape[0])
    for i in range(index.shape[0]):
        out[i] = normal_at(stream_base(key, pulse_id[i], stream), index[i])
    return out


def standard_normal(seed, pulse_id, stream: int, index) -> np.ndarray:
    """Normals of the counter-based streams at (pulse_id, index) pairs (broadcast, 1-D); for tests and studies."""
    pulse_id, index = np.broadcast_arrays(np.asarray(pulse_id, np.int64), np.asarray(index, np.int64))
    return _normals(seed_key(seed), pulse_id.ravel(), stream, index.ravel())
