"""The validation stage: the lidar-equation model beside its references.

Takes the optical model (:mod:`muls.optics`) and the Monte Carlo (:mod:`muls.montecarlo`), which knows nothing of
the model. Gives the Monte Carlo's tallies as received power beside MULS's (:mod:`.power`), the tabulated correction
of the single-scattering model (:mod:`.correction`), the acceptance check of ``muls multiscatter --json``
(:mod:`.check`), ``muls validate-pass``: the pass's waveform model beside a fresh run of the Monte Carlo that made
its tables (:mod:`.validate`), ``muls mobley1993``: the transport core against Mobley et al. (1993)'s canonical
problems (:mod:`.mobley1993`), and the tables the package ships for the presets (:mod:`.shipped_tables`,
``python3 -m muls.validation.shipped_tables``). Names load on first use.
"""

from ..infra.lazy_names import lazy_names

__all__, __getattr__, __dir__ = lazy_names(__name__, {
    "MultipleScatteringCorrection": ".correction", "mobley1993_benchmark": ".mobley1993",
    "effective_attenuation_per_m": ".power", "geometry_factor": ".power",
    "mc_power_w": ".power", "muls_power_w": ".power", "pulse_kernel": ".power", "to_power_w": ".power",
    "two_way_transmission": ".power",
})
