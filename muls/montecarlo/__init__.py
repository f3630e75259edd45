"""A semi-analytic Monte Carlo reference for the lidar return: multiple scattering, exact transceiver geometry.

MULS, like every lidar-equation model, counts single scattering only (Eqs. 4 and 7) and folds forward
scattering into an attenuation coefficient (Eq. 6). This package traces photon packets through the water
instead, with the instrument's own beam, aperture, offset and field of view, and says where the lidar
equation holds and by how much it misses (docs/multiple-scattering.md).

- :mod:`.layout`: the settings the compiled kernels share, as arrays with named positions;
- :mod:`.sampling`: per-packet random streams, free paths, directions, aperture points (compiled);
- :mod:`.estimators`: what a scattering event and a target hit send to the receiver (compiled);
- :mod:`.transport`: beam packets and their ghosts, and the variance-reduction settings (compiled);
- :mod:`.reciprocity`: the target's scattered return: receiver packets (compiled), the receiver's field
  on the target planes, its convolution with the beam hits;
- :mod:`.run`: :class:`TargetPlanes`, :func:`run_monte_carlo`, :class:`MonteCarloResult`;
- :mod:`.power`: tallies as received power through the pulse and optics, beside MULS's;
- :mod:`.correction`: :class:`MultipleScatteringCorrection`, the tabulated correction;
- :mod:`.check`: the acceptance check of ``muls multiscatter --json`` (``python3 -m muls.montecarlo.check``);
- :mod:`.slab`: the same transport in a plane-parallel water under a level surface, lit by the sun (compiled);
- :mod:`.mobley1993`: problems 1 and 2 of Mobley et al. (1993) against that transport (``muls mobley1993``).
"""

from .correction import MultipleScatteringCorrection
from .mobley1993 import DEFAULT_PHOTONS as MOBLEY1993_PHOTONS
from .mobley1993 import mobley1993_benchmark
from .power import (
    effective_attenuation_per_m,
    geometry_factor,
    mc_power_w,
    muls_power_w,
    pulse_kernel,
    to_power_w,
    two_way_transmission,
)
from .run import BATCHES, ENERGY_KEYS, TAIL_S, TIME_STEP_S, MonteCarloResult, TargetPlanes, run_monte_carlo
from .slab import SlabResult, run_slab

__all__ = [
    "BATCHES", "ENERGY_KEYS", "MOBLEY1993_PHOTONS", "TAIL_S", "TIME_STEP_S", "MonteCarloResult",
    "MultipleScatteringCorrection", "SlabResult", "TargetPlanes", "effective_attenuation_per_m", "geometry_factor",
    "mc_power_w", "mobley1993_benchmark", "muls_power_w", "pulse_kernel", "run_monte_carlo", "run_slab", "to_power_w",
    "two_way_transmission",
]
