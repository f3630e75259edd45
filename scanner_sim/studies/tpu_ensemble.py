"""The uncertainty checked over an ensemble of passes: N passes of one scene that differ only in their seeds, their
judged points pooled (``scanner-sim uncertainty --seeds N``, docs/uncertainty.md).

A navigation error that drifts over seconds (a first-order Gauss-Markov process of correlation time tau) is nearly
one value over a pass much shorter than tau, so one such pass's share within TVU is that of one draw of it; the TPU's
variances describe the error's distribution, which only many draws sample. Member i's seeds are the first two 64-bit
words, halved, of ``SeedSequence(seed, spawn_key=(i,))`` (the rule a dataset draws its scenes' seeds by,
:func:`~scanner_sim.runs.dataset_draw.scene_seeds`): its ``survey.seed`` (the instrument's noise) and its
``platform.navigation_noise.seed``. The members share the built scene, its BVH and the TPU model
(:meth:`~scanner_sim.survey.setup.PassSetup.with_seeds`): each member's points are those ``scanner-sim run`` gives
with its seeds, judged by one ranging table, measured once with the seed they derive from.
"""

from __future__ import annotations

import numpy as np

from scanner_sim.config import SceneConfig
from scanner_sim.runs.dataset_draw import scene_seeds
from scanner_sim.survey.pipeline import pass_chunks, warm_up
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.survey.tpu_calibration import UncertaintySink

#: Most passes in one ensemble. The spread of the members' shares is what many passes add: with N members the
#: standard deviation of the share within TVU is known to a relative 1/sqrt(2 (N - 1)), 0.7 % at 10,000, and the
#: pooled share's sampling error is far below the 1 % the shares are printed to. Beyond, passes add time only (a
#: pass takes a second or more: 10,000 are hours) and the JSON lists every member.
MAX_ENSEMBLE_PASSES = 10_000


def check_ensemble_size(count: int, key: str = "count") -> None:
    """Refuse an ensemble of more than :data:`MAX_ENSEMBLE_PASSES` passes (ValueError, one line naming ``key``)."""
    if count > MAX_ENSEMBLE_PASSES:
        raise ValueError(f"{key} = {count}: at most {MAX_ENSEMBLE_PASSES:,} passes; their spread is then known to "
                         "0.7 % and more passes add hours, not precision")


def ensemble_seeds(seed: int, count: int) -> list[tuple[int, int]]:
    """(survey seed, navigation noise seed) of each of ``count`` members derived from ``seed`` (module doc)."""
    return [scene_seeds(seed, i)[1:3] for i in range(count)]


def ensemble_calibration(config: SceneConfig, options: PassOptions, count: int) -> dict:
    """The ``uncertainty`` figures (:meth:`UncertaintySink.figures`) of ``count`` passes of ``config`` under
    ``options`` pooled, with the seeds they were derived from (``options.seed`` or the scene's ``survey.seed``) and
    used, and each member's own shares, so a reader sees their spread. ``ranging`` is the table every member's TPU
    uses (measured with the base seed)."""
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"count: {count!r} is not allowed; the number of passes is an integer >= 1")
    check_ensemble_size(count)
    base = PassSetup.build(config, options)
    warm_up(base, options)
    pooled, members, pulses, points = UncertaintySink(base.tpu), [], 0, 0
    for survey_seed, navigation_seed in ensemble_seeds(base.seed, count):
        setup = base.with_seeds(survey_seed, navigation_seed)
        own = UncertaintySink(setup.tpu)
        for chunk in pass_chunks(setup, options):
            own.add(chunk)
            pooled.add(chunk)
            pulses += chunk.slots.size
            points += len(chunk.points.xyz)
        cal = own.figures()["calibration"]
        members.append({"seed": survey_seed, "navigation_seed": navigation_seed, "points": cal["points"],
                        "vertical_within_tvu": cal["vertical_within_tvu"],
                        "horizontal_within_thu": cal["horizontal_within_thu"]})
    shares = np.array([m["vertical_within_tvu"] for m in members if m["vertical_within_tvu"] is not None])
    spread = ({"min": float(shares.min()), "max": float(shares.max()), "std": round(float(shares.std()), 4)}
              if shares.size else {"min": None, "max": None, "std": None})
    return {"scene": config.name, "water": base.water_name, "seed": base.seed, "pulses": pulses, "points": points,
            **pooled.figures(), "ensemble": {"members": count, "seeds": members, "vertical_within_tvu_spread": spread}}
