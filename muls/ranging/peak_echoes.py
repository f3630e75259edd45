"""Which echo explains each peak of the peak search (:mod:`muls.ranging.peaks`): the one giving the most noise-free power
there among the echoes that can make a peak there, the way trimesh returns ``index_ray`` for each hit."""

from __future__ import annotations

import numpy as np

from ..infra.blocks import in_blocks
from ..infra.runtime import kernel
from ..optics.optical_model import Echoes
from ..optics.sample_kernels import pulse_value


def dominant_echo(pulse, time_s, need_w, echoes: Echoes, basis, shape) -> np.ndarray:
    """(n,) int64: the :class:`PulseBatch` return whose echo explains each peak (``pulse`` (n,) batch index,
    ``time_s`` (n,) [s]; ``shape`` the instrument's :class:`muls.instrument.pulse.PulseShape`), or -1 where the echoes together
    give less than ``need_w`` (n,) [W] there (a footprint's sub-ray echoes add up: one of them alone may be faint).

    The echo that explains a peak is the one giving the most noise-free power there among the echoes that can
    make a peak there: those still rising or within half their maximum past it (``PulseShape.fall_to_half_s``). At a
    peak the signal's slope is zero, so an echo further down its tail, whose slope is negative, cannot have
    made it, however much power it still gives (a clipped echo's tail 10 ns on still gives more than a weak
    echo's peak). Where those echoes together give less than ``need_w``, the most powerful echo of all is
    taken."""
    pulse, time_s, need_w = np.asarray(pulse, np.int64), np.asarray(time_s, float), np.asarray(need_w, float)
    best = np.concatenate(in_blocks(
        lambda a, b: _dominant(pulse[a:b], time_s[a:b], need_w[a:b], echoes.offsets, echoes.delay_s, echoes.energy_j,
                               basis, shape.duration_s, shape.peak_delay_s + shape.fall_to_half_s), pulse.shape[0]))
    out = np.full(best.shape, -1, np.int64)
    out[best >= 0] = echoes.source[best[best >= 0]]
    return out


@kernel(nogil=True)
def _dominant(pulse, time_s, need_w, offsets, delay, energy, basis, extent, making):
    """Index into the echoes of the echo explaining each peak, -1 for none (see :func:`dominant_echo`); an echo
    can make a peak up to ``making`` [s] after its start."""
    out = np.full(pulse.shape[0], -1, np.int64)
    for i in range(pulse.shape[0]):
        p = pulse[i]
        total, top, best = 0.0, 0.0, -1
        near, near_top, near_best = 0.0, 0.0, -1
        for j in range(offsets[p], offsets[p + 1]):
            u = time_s[i] - delay[j]
            if 0.0 <= u < extent:
                power = energy[j] * pulse_value(u, basis)
                total += power
                if power > top:
                    top, best = power, j
                if u <= making:
                    near += power
                    if power > near_top:
                        near_top, near_best = power, j
        if total >= need_w[i]:
            out[i] = near_best if near >= need_w[i] else best
    return out
