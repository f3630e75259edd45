"""The registry of ``muls``'s subcommands: for each, its one-line help and the module of :mod:`muls.cli` that adds
its options and runs it (that module's ``BUILDERS``). The module is imported only when its subcommand is parsed,
so that ``muls --help`` imports no study, Monte Carlo or plotting code; adding a subcommand is a line here and a
builder there."""

from __future__ import annotations

#: name -> (module under muls.cli, one-line help), in the order ``muls --help`` lists them.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "waveform": ("studies", "CH0-CH3 of one pulse, noisy over noise-free (paper Figs. 7, 8)"),
    "maxrange": ("studies", "maximum detectable range, single vs multi-channel (paper Table 3)"),
    "precision": ("studies", "range precision and mean deviation per channel (paper Table 2)"),
    "edge-bias": ("studies", "range bias of a plate at the blind-zone edge, every water, and its cause"),
    "experiment": ("studies", "the paper's pond or pool test predicted (Table 2, Figs. 7, 8, 10, 11)"),
    "budget": ("studies", "photon budget of every study point; where reported ranges exceed it"),
    "coaxial": ("studies", "column backscatter, coaxial vs non-coaxial (paper Fig. 13)"),
    "bench": ("studies", "pulses per second of simulate on this machine"),
    "multiscatter": ("montecarlo", "Monte Carlo with multiple scattering beside MULS, one plate"),
    "multiscatter-study": ("montecarlo", "where single scattering fails: MC / MULS per water and range"),
    "mobley1993": ("montecarlo", "the Monte Carlo's transport against Mobley et al. (1993), problems 1 and 2"),
    "validate-pass": ("montecarlo", "consistency check of the scattering tables: the pass's waveform model against a "
                       "fresh run of the Monte Carlo that made them, five waters, 2-30 m"),
    "sensitivity": ("sensitivity", "band of the echo and the column over a family of phase functions, 2-20 m"),
    "pond-unknowns": ("sensitivity", "the pond's detections as each input the paper leaves unknown moves"),
}
