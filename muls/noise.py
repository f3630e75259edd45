"""Counter-based random numbers: each draw is a pure function of (seed, pulse id, stream, sample index).

Why not a sequential generator: the windowed and full-record modes synthesise different subsets of samples,
and a pass is cut into chunks of any size; both must see the same noise at the same sample. A counter-based
stream (SplitMix64 finaliser over a Weyl sequence, the generator of Steele et al. 2014) gives that for free
and costs a few integer operations per draw inside the numba kernels.
"""

from __future__ import annotations

import numba
import numpy as np

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_TWO_PI = 2.0 * np.pi
_INV_2_32 = 1.0 / 4294967296.0

#: Stream numbers: the sampling phase, the CH0 noise, then one stream per pair of signal channels (the two
#: outputs of one Box-Muller draw serve channels 2j and 2j + 1).
PHASE_STREAM = 0
REFERENCE_STREAM = 1
FIRST_SIGNAL_STREAM = 2


def seed_key(seed) -> np.uint64:
    """64-bit key of a run from an int seed or a ``numpy.random.Generator`` (which is advanced once)."""
    if isinstance(seed, np.random.Generator):
        seed = int(seed.integers(0, 2**63))
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed = {seed!r}: must be a non-negative integer or a numpy.random.Generator")
    return np.uint64(_mix(np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF)))


@numba.njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def stream_base(key, pulse_id, stream):
    """State of one (pulse, stream) sequence."""
    return _mix(key ^ _mix(np.uint64(pulse_id) * np.uint64(64) + np.uint64(stream) + _GAMMA))


@numba.njit(cache=True, inline="always")
def uniform_at(base, index):
    """Uniform in [0, 1) at position ``index`` of a stream."""
    h = _mix(base + (np.uint64(index) + np.uint64(1)) * _GAMMA)
    return float(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, inline="always")
def normal_at(base, index):
    """Standard normal at position ``index`` of a stream (Box-Muller on one 64-bit draw, |x| < 6.7)."""
    h = _mix(base + (np.uint64(index) + np.uint64(1)) * _GAMMA)
    u1 = (float(h >> np.uint64(32)) + 0.5) * _INV_2_32
    u2 = float(h & np.uint64(0xFFFFFFFF)) * _INV_2_32
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(_TWO_PI * u2)


@numba.njit(cache=True, inline="always")
def normal_pair_at(base, index):
    """Two independent standard normals at position ``index`` of a stream (both Box-Muller outputs)."""
    h = _mix(base + (np.uint64(index) + np.uint64(1)) * _GAMMA)
    u1 = (float(h >> np.uint64(32)) + 0.5) * _INV_2_32
    u2 = float(h & np.uint64(0xFFFFFFFF)) * _INV_2_32
    r = np.sqrt(-2.0 * np.log(u1))
    return r * np.cos(_TWO_PI * u2), r * np.sin(_TWO_PI * u2)


@numba.njit(cache=True)
def _normals(key, pulse_id, stream, index):
    out = np.empty(index.shape[0])
    for i in range(index.shape[0]):
        out[i] = normal_at(stream_base(key, pulse_id[i], stream), index[i])
    return out


def standard_normal(seed, pulse_id, stream: int, index) -> np.ndarray:
    """Normals of the counter-based streams at (pulse_id, index) pairs (broadcast, 1-D); for tests and studies."""
    pulse_id, index = np.broadcast_arrays(np.asarray(pulse_id, np.int64), np.asarray(index, np.int64))
    return _normals(seed_key(seed), pulse_id.ravel(), stream, index.ravel())
