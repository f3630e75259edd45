"""The far channel's range gate as the pass sets it: an operator's rule where the scene gives none, and a warning
where the scene's gate shuts out the echoes the survey can produce.

Both read the same sample of the pass: the beam axes of pulses spread over the whole pass (:func:`echo_span`) cast
into the scene at set-up, whose first hits give the two-way delays at which the survey's echoes arrive. The rule
(:func:`rule_gate`) is what an operator of a gated far-field PMT does: open the gate :data:`GATE_LEAD_S` before
the nearest of those echoes, so that its rise and the column just before it are inside, and close it
:data:`GATE_LAG_S` after the farthest one's pulse has passed. It follows the altitude, the scan sector and the
relief, and the water through its speed of light.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from scanner_sim.config.errors import SetupWarning

#: [s] The gate opens this long before the nearest echo's start: two pulse widths, room for the echo's rise and
#: for the navigation's and the relief's variation between the sampled pulses.
GATE_LEAD_S = 20e-9
#: [s] ... and closes this long after the farthest echo's pulse has passed (its multiply scattered tail).
GATE_LAG_S = 20e-9
#: Scan periods sampled over the pass, and pulses kept of each: 2,000 beam axes at most.
SAMPLED_PERIODS = 40
PULSES_PER_PERIOD = 50
#: A gate that leaves more than this share of the sampled echoes outside draws a warning.
SHUT_OUT_SHARE = 0.05


@dataclass(frozen=True)
class EchoSpan:
    """Two-way delays [s] (k,) of the first hits of sampled beam axes of a pass, ascending; empty when none hits."""

    delays_s: np.ndarray

    @property
    def near_s(self) -> float:
        return float(self.delays_s[0])

    @property
    def far_s(self) -> float:
        return float(self.delays_s[-1])


def echo_span(target, trajectory, scanner, speed_m_s: float, first_slot: int, end_slot: int) -> EchoSpan:
    """The delays of the echoes of a sample of the pass's pulses: :data:`SAMPLED_PERIODS` scan periods spread evenly
    over slots ``first_slot`` .. ``end_slot`` - 1, up to :data:`PULSES_PER_PERIOD` fired pulses of each, their beam
    axes (true poses) cast into ``target`` (a :class:`~scanner_sim.rays.cast.CastScene`). ``speed_m_s``: light in
    the water [m/s]."""
    rate = scanner.pulse_rate_hz
    t0, t1 = first_slot / rate, end_slot / rate
    period = 1.0 / scanner.scan_rate_hz
    starts = np.linspace(t0, max(t0, t1 - period), SAMPLED_PERIODS)
    slots = []
    for start in np.unique(starts):  # a few dozen windows, not a loop per pulse
        fired = scanner.pulse_slots(start, min(t1, start + period))
        if fired.size:
            slots.append(fired[np.unique(np.linspace(0, fired.size - 1, PULSES_PER_PERIOD).astype(np.int64))])
    if not slots:
        return EchoSpan(np.zeros(0))
    slots = np.unique(np.concatenate(slots))
    beam_o, beam_d, _, _, _ = scanner.world_rays(trajectory.poses(slots / rate))
    scene = target.scene
    _, _, distance = target.caster.first_hits((beam_o - scene.local_origin).astype(np.float32),
                                              beam_d.astype(np.float32))
    return EchoSpan(np.sort(2.0 * distance.astype(np.float64) / speed_m_s))


def rule_gate(span: EchoSpan, pulse_duration_s: float) -> tuple[float, float] | None:
    """(delay [s], width [s]) of the operator's gate for ``span`` (module doc), whole nanoseconds; None when no
    sampled beam meets anything (the instrument's own gate is kept)."""
    if span.delays_s.size == 0:
        return None
    open_s = max(0.0, math.floor((span.near_s - GATE_LEAD_S) * 1e9) * 1e-9)
    close_s = math.ceil((span.far_s + pulse_duration_s + GATE_LAG_S) * 1e9) * 1e-9
    return open_s, close_s - open_s


def warn_if_shut_out(span: EchoSpan, gate_open_s: float, gate_close_s: float, pulse_duration_s: float,
                     key: str = "instrument.gate_delay_ns") -> None:
    """Warn (:class:`SetupWarning` naming ``key``) when more than :data:`SHUT_OUT_SHARE` of the sampled echoes start
    before the gate opens or end after it closes: they reach only the ungated channels."""
    d = span.delays_s
    if d.size == 0:
        return
    early = d < gate_open_s
    late = d + pulse_duration_s > gate_close_s
    shut = np.mean(early | late)
    if shut <= SHUT_OUT_SHARE:
        return
    where = "before it opens" if early.sum() >= late.sum() else "after it closes"
    warnings.warn(SetupWarning(
        f"{key} = {gate_open_s * 1e9:g}: the far channel's gate ({gate_open_s * 1e9:g} to {gate_close_s * 1e9:g} ns) "
        f"shuts out {shut:.0%} of the echoes this survey gives (they arrive {d[0] * 1e9:.0f} to {d[-1] * 1e9:.0f} ns, "
        f"most {where}); leave the gate unset for the operator's rule, or open it about {(d[0] - GATE_LEAD_S) * 1e9:.0f} "
        "ns"), stacklevel=3)
