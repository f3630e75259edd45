"""The Monte Carlo's transport core against a published benchmark: problems 1 and 2 of Mobley et al. (1993).

Mobley, Gentili, Gordon, Jin, Kattawar, Morel, Reinersman, Stamnes and Stavn (1993), "Comparison of numerical
models for computing underwater light fields", Applied Optics 32(36), 7484-7504, compared seven codes (the
invariant-imbedding model II, the discrete-ordinate model DO and five Monte Carlo codes MC1-MC5) on a set of
canonical problems. Its Section 3 and Table 3 define them; problems 1 and 2 are (every value below cites it):

- homogeneous, infinitely deep water, a level air-water surface, water index n = 1.340, a black sky;
- the sun a point source at zenith angle 60 deg, giving E_perp = 1 W m^-2 nm^-1 on a plane normal to its rays
  just above the surface (Ed(air) = 0.5 W m^-2 nm^-1);
- no inelastic scattering; single-scattering albedo 0.9 (highly scattering) or 0.2 (highly absorbing);
- problem 1: the Rayleigh phase function 3/(16 pi) (1 + cos^2 psi) (Eq. 3); problem 2: the particle phase
  function of its Table 2 (Petzold's average, :func:`muls.water.phase.mobley1993_particle`).

Depths are optical depths tau = c z; here c = 1 per m, so z [m] = tau.

Its Table 5 gives, at tau = 1, 5 and 10, the average over the codes of Ed (downward plane irradiance), Eou
(upward scalar irradiance) and Lu (nadir-viewing radiance, light travelling straight up) and the ratio s/x of
the codes' sample standard deviation (with N - 1) to that average, with N the number of codes. The paper
tabulates no code's own value (its Figs. 2 and 3 plot them). So the range of the codes is bounded from the
table: no one of N values lies farther from their mean than s (N - 1) / sqrt(N) (Samuelson 1968, "How deviant
can you be?", J. Am. Stat. Assoc. 63, 1522). With the half unit of the last printed digit of the mean and of
s/x added, the interval [paper_min, paper_max] is certain to hold all N codes' values: the tightest interval
the published table allows, and never narrower than the codes' true spread.
"""

from __future__ import annotations

import math
import re
import time

from ..infra.errors import ParameterError
from ..montecarlo.slab import STREAM, run_slab

SOURCE = ("Mobley, Gentili, Gordon, Jin, Kattawar, Morel, Reinersman, Stamnes and Stavn (1993), Comparison of "
          "numerical models for computing underwater light fields, Appl. Opt. 32(36), 7484-7504, Table 5")

SUN_ZENITH_DEG = 60.0  # Mobley et al. (1993) Section 3 (d)
WATER_INDEX = 1.340  # Section 3: "The real index of refraction of the water is n = 1.340"
ATTENUATION_PER_M = 1.0  # c: the paper gives depths as optical depths tau = c z; any c gives the same tau
#: The phase function of each problem (Table 3: problem 1 Eq. 3, problem 2 Table 2).
PROBLEM_PHASE = {1: "rayleigh", 2: "mobley1993_particle"}
ALBEDOS = (0.9, 0.2)  # Table 3
QUANTITIES = ("Ed", "Eou", "Lu")  # Table 5's columns
OPTICAL_DEPTHS = (1.0, 5.0, 10.0)  # Table 5's rows

#: Mobley et al. (1993) Table 5 (p. 7496), problems 1 and 2, as printed ("3.66-1" is 3.66e-1): for each
#: (problem, albedo) the number of codes N, then per optical depth the averages of Ed, Eou, Lu and their s/x.
#: Ed and Eou are in W m^-2 nm^-1, Lu in W m^-2 sr^-1 nm^-1, for E_perp = 1 W m^-2 nm^-1. Transcribed from a
#: scan of the article, a copy of which is in the public GitHub repository mgimond/aomc
#: (comparison/vol32n36_pp7484.pdf, commit da63257); that repository's independent transcription
#: (comparison/mobley_problems/Mobley_comparisons.xlsx) agrees value for value.
TABLE5 = {
    (1, 0.9): (7, {1.0: (("3.66-1", "0.002"), ("3.72-1", "0.005"), ("4.85-2", "0.015")),
                   5.0: (("4.33-2", "0.003"), ("4.35-2", "0.007"), ("5.59-3", "0.052")),
                   10.0: (("3.16-3", "0.015"), ("3.20-3", "0.038"), ("4.37-4", "0.091"))}),
    (1, 0.2): (7, {1.0: (("1.41-1", "0.001"), ("1.34-2", "0.003"), ("1.72-3", "0.044")),
                   5.0: (("1.07-3", "0.005"), ("1.00-4", "0.039"), ("1.37-5", "0.288")),
                   10.0: (("2.93-6", "0.102"), ("3.00-7", "0.308"), ("3.39-8", "0.197"))}),
    (2, 0.9): (7, {1.0: (("4.13-1", "0.001"), ("9.31-2", "0.021"), ("6.99-3", "0.063")),
                   5.0: (("1.87-1", "0.005"), ("4.63-2", "0.017"), ("3.26-3", "0.055")),
                   10.0: (("6.85-2", "0.010"), ("1.65-2", "0.014"), ("1.21-3", "0.109"))}),
    (2, 0.2): (7, {1.0: (("1.62-1", "0.000"), ("9.66-4", "0.023"), ("5.47-5", "0.060")),
                   5.0: (("2.27-3", "0.002"), ("1.37-5", "0.063"), ("6.24-7", "0.355")),
                   10.0: (("1.30-5", "0.047"), ("7.28-8", "0.187"), ("4.02-9", "0.248"))}),
}
#: Table 5's exceptions to N (printed beside the Lu value of the row): three Monte Carlo codes had too few
#: photons left for Lu at tau = 10 in problem 1 with albedo 0.2 (Section 4), and only some codes gave Lu deep
#: in problem 2 with albedo 0.2.
TABLE5_LU_MODELS = {(1, 0.2, 10.0): 4, (2, 0.2, 5.0): 6, (2, 0.2, 10.0): 5}

#: Photons per run of ``muls mobley1993`` by default (docs/multiple-scattering.md gives the errors it leaves).
DEFAULT_PHOTONS = 2_000_000
#: The runs in absorbing water trace this many times the photons: a photon costs 8 to 20 times less there (it
#: is absorbed sooner), and the upwelling light, scattered backwards once in 50 events by Petzold's phase
#: function, is the noisiest of all the values.
PHOTON_FACTOR = {0.9: 1, 0.2: 5}


def parse_printed(text: str) -> tuple[float, float]:
    """A number as Table 5 prints it ("3.66-1" is 3.66e-1, "0.002" has no exponent) and the half unit of its
    last printed digit."""
    match = re.fullmatch(r"(\d+\.(\d+))([+-]\d+)?", text)
    if match is None:
        raise ParameterError(f"printed value {text!r}: must look like '3.66-1' or '0.002'")
    scale = 10.0 ** int(match.group(3) or 0)
    return float(match.group(1)) * scale, 0.5 * 10.0 ** -len(match.group(2)) * scale


def codes_range(mean: str, rel_sd: str, n_models: int) -> tuple[float, float]:
    """(paper_min, paper_max): bounds on every one of ``n_models`` values whose average and s/x Table 5 prints.

    No value lies farther than s (N - 1) / sqrt(N) from the mean (Samuelson 1968); the mean and s/x may each
    be off by the half unit of their last printed digit.
    """
    m, dm = parse_printed(mean)
    r, dr = parse_printed(rel_sd)
    k = (n_models - 1) / math.sqrt(n_models)
    return max(0.0, (m - dm) * (1.0 - k * (r + dr))), (m + dm) * (1.0 + k * (r + dr))


def paper_rows() -> list[dict]:
    """Table 5 for problems 1 and 2, one dict per value: problem, albedo, quantity, optical depth, the printed
    mean and s/x, N, and the codes' range (:func:`codes_range`)."""
    rows = []
    for (problem, albedo), (n, by_depth) in TABLE5.items():
        for q, quantity in enumerate(QUANTITIES):
            for tau, values in by_depth.items():
                mean, rel_sd = values[q]
                models = TABLE5_LU_MODELS.get((problem, albedo, tau), n) if quantity == "Lu" else n
                lo, hi = codes_range(mean, rel_sd, models)
                rows.append({"problem": problem, "albedo": albedo, "quantity": quantity, "optical_depth": tau,
                             "paper_mean": parse_printed(mean)[0], "paper_rel_sd": parse_printed(rel_sd)[0],
                             "paper_models": models, "paper_min": lo, "paper_max": hi})
    return rows


def judge(value: float, sigma: float, paper_min: float, paper_max: float) -> bool | None:
    """Whether ``value`` lies in [paper_min - 2 sigma, paper_max + 2 sigma]; None (not judged) where the Monte Carlo's
    2 sigma is wider than the codes' range, or not a positive number (no photon, or every batch alike)."""
    if not 0.0 < 2.0 * sigma <= paper_max - paper_min:
        return None
    return paper_min - 2.0 * sigma <= value <= paper_max + 2.0 * sigma


def mobley1993_benchmark(photons: int = DEFAULT_PHOTONS, seed: int = 0) -> dict:
    """Run problems 1 and 2 (albedos 0.9 and 0.2) and set each Table 5 value beside the Monte Carlo's.

    photons: per run at albedo 0.9, times :data:`PHOTON_FACTOR` at 0.2. Returns {"problems": [record, ...],
    "source", "photons", "seed", "seconds", "energy"}; a record has problem, albedo, quantity, optical_depth, value,
    mc_sigma (its standard error), paper_min, paper_max, paper_mean, paper_rel_sd, paper_models, ``within``
    (value inside [paper_min - 2 mc_sigma, paper_max + 2 mc_sigma]; None, not judged, where 2 mc_sigma is wider
    than the codes' range or not positive: a band widened past twice the codes' own cannot tell a wrong value,
    :func:`judge`) and the photons of its run. energy: each
    run's budget (:class:`muls.montecarlo.slab.SlabResult`).
    """
    t0 = time.perf_counter()
    runs = {}
    for i, key in enumerate(TABLE5):
        problem, albedo = key
        runs[key] = run_slab(PROBLEM_PHASE[problem], albedo, OPTICAL_DEPTHS, ATTENUATION_PER_M, SUN_ZENITH_DEG,
                             WATER_INDEX, packets=photons * PHOTON_FACTOR[albedo], seed=seed,
                             stream=STREAM + i)  # each run on its own stream: independent
    records = []
    for row in paper_rows():
        run = runs[(row["problem"], row["albedo"])]
        k = OPTICAL_DEPTHS.index(row["optical_depth"])
        value, sigma = float(run.mean[row["quantity"]][k]), float(run.sigma[row["quantity"]][k])
        within = judge(value, sigma, row["paper_min"], row["paper_max"])
        records.append({**{key: row[key] for key in ("problem", "albedo", "quantity", "optical_depth")},
                        "value": value, "mc_sigma": sigma, "paper_min": row["paper_min"],
                        "paper_max": row["paper_max"], "paper_mean": row["paper_mean"],
                        "paper_rel_sd": row["paper_rel_sd"], "paper_models": row["paper_models"], "within": within,
                        "photons": run.packets})
    return {"problems": records, "source": SOURCE, "photons": int(photons), "seed": int(seed),
            "seconds": time.perf_counter() - t0,
            "energy": [{"problem": p, "albedo": a, **run.energy} for (p, a), run in runs.items()]}

