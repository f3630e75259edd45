"""The Monte Carlo stage: photon packets traced through the water with the instrument's own transceiver.

Takes a :class:`~muls.water.properties.Water` (with its phase function) and a transceiver geometry (an
:class:`~muls.instrument.description.Instrument`'s). Gives time-resolved tallies of the echo of flat plates and of
the water column, all orders of scattering (:func:`.run.run_monte_carlo`), the same transport in a plane-parallel
water lit by the sun (:func:`.slab.run_slab`), and the tables the optical model applies per water and receiver
(:mod:`.scattering_tables`, found, cached or built by :mod:`.tables`). It knows nothing of the lidar equation: the
optical model sits above it and takes its tables, and :mod:`muls.validation` compares the two.

- :mod:`.layout`: the settings the compiled kernels share, as arrays with named positions;
- :mod:`.sampling`: per-packet random streams, free paths, directions, aperture points (compiled);
- :mod:`.estimators`: what a scattering event and a target hit send to the receiver (compiled);
- :mod:`.transport`: beam packets and their ghosts, and the variance-reduction settings (compiled);
- :mod:`.reciprocity`: the target's scattered return: receiver packets (compiled), the receiver's field
  on the target planes, its convolution with the beam hits;
- :mod:`.run`: :class:`TargetPlanes`, :func:`run_monte_carlo`, :class:`MonteCarloResult`;
- :mod:`.slab`: the transport in a plane-parallel water under a level surface, lit by the sun (compiled);
- :mod:`.scattering_tables`: :class:`ScatteringTables`, what one run says about a water and a receiver;
- :mod:`.tables`: the run behind those tables, and where they are found (memory, shipped, user cache).

Names load on first use: importing the package (or its tables) compiles and imports no kernel.
"""

from ..infra.lazy_names import lazy_names

__all__, __getattr__, __dir__ = lazy_names(__name__, {
    "BATCHES": ".run", "ENERGY_KEYS": ".run", "TAIL_S": ".run", "TIME_STEP_S": ".run", "MonteCarloResult": ".run",
    "TargetPlanes": ".run", "run_monte_carlo": ".run", "SlabResult": ".slab", "run_slab": ".slab",
    "ScatteringTables": ".scattering_tables", "find_or_build_tables": ".tables",
})
