"""How numba's parallel kernels share the cores with the threads beside them.

A pass runs its ray stage in a thread beside the physics, whose digitiser and peak search are numba-parallel
(OpenMP threading layer here). By default an OpenMP worker keeps spinning for a while after each parallel region,
waiting for the next one, and so takes a core from the ray thread for nothing. With ``OMP_WAIT_POLICY=PASSIVE``
idle workers sleep at once. Measured on the 2-core machine (``fast`` on cable_survey, 200,000 pulses, the chunk
loop alone): 112,000 and 132,000 pulses/s spinning against 134,000 and 160,000 passive, at fewer cores used. A
parallel region here lasts tens of milliseconds, so waking the workers costs nothing that shows.

The policy is read once, when OpenMP loads (at numba's first parallel launch), so importing :mod:`muls` sets it
before any kernel runs; a value the user set wins.
"""

from __future__ import annotations

import os

#: The OpenMP wait policy set unless the environment has one.
OMP_WAIT_POLICY = "PASSIVE"


def configure() -> None:
    """Set ``OMP_WAIT_POLICY`` to :data:`OMP_WAIT_POLICY` unless it is set already."""
    os.environ.setdefault("OMP_WAIT_POLICY", OMP_WAIT_POLICY)


configure()
