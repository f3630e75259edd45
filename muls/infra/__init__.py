"""The ground floor of the physics: what every stage uses and none of them is about.

Takes nothing from the other stages. Gives the process's runtime set-up and the compiled-kernel decorator
(:mod:`.runtime`), the error hierarchy and value checks (:mod:`.errors`), the memory a command may plan on
(:mod:`.memory`), the command-line plumbing both command lines share (:mod:`.command`), table lookups
(:mod:`.lookup`), a batch's kernels in blocks on threads (:mod:`.blocks`), the first-order recursive filter
(:mod:`.filters`), counter-based random numbers keyed by (seed, pulse, stream, sample) (:mod:`.noise`), the one
atomic file writer (:mod:`.atomic`), Brent's root finder (:mod:`.roots`), the compile-time report
(:mod:`.compile_times`) and the packages' names loaded on first use (:mod:`.lazy_names`).
"""
