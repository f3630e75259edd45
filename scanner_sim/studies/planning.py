"""Survey planning (docs/planning.md): the plan of least survey time that meets an IHO S-44 order over a site, per
water type.

The method, in four steps:

1. *Sample passes.* Short straight lines along the survey's heading, placed over the survey area where the seabed
   has data across the whole swath, chosen nearest the depth quantiles of the area (the site's dominant depth
   range), one pass per water x altitude x speed x line, run as Dask tasks like a campaign.
2. *Profiles.* Each pass's per-order S-44 tally (coverage_grid.npz's strictest order per plan cell), binned by the
   cell centre's across-track offset from its line over the line's central stretch, pooled over the lines: per
   offset, the share of cells complying with the order, the share covered, and the gap causes.
3. *Candidates.* For each water x altitude x speed, the line spacings that span the area's width with one line
   fewer at each step (:func:`~.planning_prediction.spacing_ladder`); a spacing's predicted compliance is the mean
   share over the offsets a cell can have from its lines (:func:`~.planning_prediction.predicted_share`); the widest
   spacing whose prediction holds the required share is that altitude and speed's candidate, the next wider one is
   kept rejected. Survey time = (lines x line length + turns) / speed, a turn being the lawnmower's leg across to the
   next line (:func:`~.planning_prediction.survey_time_s`).
4. *Confirmation.* Per water, the least-time candidate flown as a lawnmower over the area (or a centred sample of
   it when the whole would exceed ``max_confirm_pulses``) and judged on the area's cells with seabed data; a
   candidate confirmed short is replaced by the next one in time order.

Steps 1 and 2 are in :mod:`~scanner_sim.studies.planning_sampling`, step 3 in
:mod:`~scanner_sim.studies.planning_prediction`, step 4 in :mod:`~scanner_sim.studies.planning_confirmation`; this
module checks the inputs, runs the steps and gathers the plan.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from muls.infra.errors import ParameterError
from muls.presets import water_preset
from scanner_sim.config import SceneConfig
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import GAP_CAUSES
from scanner_sim.runs.cluster import maybe_client
from scanner_sim.runs.jobs import run_jobs
from scanner_sim.runs.tasks import PassJob
from scanner_sim.studies.defaults import DEFAULT_REQUIRED_SHARE, DEFAULT_WATERS
from scanner_sim.studies.planning_confirmation import DEFAULT_FEATURE_CUBES, confirm_plans, confirmed_cause
from scanner_sim.studies.planning_prediction import Candidate, best_order_and_cause, ladder_candidates
from scanner_sim.studies.planning_sampling import (
    BIN_M,
    Profile,
    SiteArea,
    all_ran,
    check_reach,
    choose_sample_lines,
    half_reach_m,
    pass_grid,
    profile_of,
    sample_config,
    site_area,
)
from scanner_sim.survey.setup import PassOptions
from scanner_sim.survey.setup_cache import cached_scene

#: Altitudes and speeds tried by default, as multiples of the scene's own.
DEFAULT_ALTITUDE_FACTORS = (0.5, 1.0, 1.5)
DEFAULT_SPEED_FACTORS = (0.5, 1.0)


@dataclass(frozen=True)
class WaterPlan:
    """The outcome for one water: ``chosen`` (None: not achievable), every candidate tried, and, when not achievable,
    the best order the sample passes predict it meets and the cause that limits it."""

    water: str
    chosen: Candidate | None
    candidates: tuple[Candidate, ...]
    confirmation: dict | None
    best_order: str | None = None
    limiting_cause: str | None = None

    @property
    def achievable(self) -> bool:
        return self.chosen is not None

    def as_json(self) -> dict:
        return {"water": self.water, "achievable": self.achievable,
                "chosen": None if self.chosen is None else self.chosen.as_json(),
                "confirmation": self.confirmation, "best_order": self.best_order,
                "limiting_cause": self.limiting_cause, "candidates": [c.as_json() for c in self.candidates]}


@dataclass(frozen=True)
class SurveyPlan:
    """The planner's answer (``plan.json``): per water a :class:`WaterPlan`, the site, the settings, the sample lines,
    the profiles measured and the passes run; ``config`` the scene planned, ``confirm_configs`` by water the scene
    of the chosen plan's confirmation pass."""

    scene: str
    order: str
    area: SiteArea
    required_share: float
    sample_lines: tuple[tuple[tuple[float, float], tuple[float, float]], ...]
    waters: tuple[WaterPlan, ...]
    profiles: tuple[Profile, ...]
    sample_passes: int
    confirmation_passes: int
    config: SceneConfig = field(compare=False)
    confirm_configs: dict = field(default_factory=dict, compare=False)

    def as_json(self) -> dict:
        order = next(o for o in s44.ORDERS if o.name == self.order)
        return {"scene": self.scene, "order": self.order, "order_figures": order.as_json(),
                "required_share": self.required_share,
                "area": {"center_m": list(self.area.center_m), "size_m": list(self.area.size_m),
                         "heading_deg": self.area.heading_deg},
                "sample_lines_m": [[list(a), list(b)] for a, b in self.sample_lines],
                "sample_passes": self.sample_passes, "confirmation_passes": self.confirmation_passes,
                "waters": [w.as_json() for w in self.waters], "profiles": [p.as_json() for p in self.profiles]}


def order_index(order: str) -> int:
    """Index of ``order`` in s44.ORDERS; a ParameterError naming the allowed ones otherwise."""
    if order not in s44.ORDER_NAMES:
        raise ParameterError(f"order = {order!r}: no such IHO S-44 order; must be one of {', '.join(s44.ORDER_NAMES)}")
    return s44.ORDER_NAMES.index(order)


def plan_survey(scene, order: str = "special", waters=DEFAULT_WATERS,
                altitudes_m=None, speeds_m_s=None, *, required_share: float = DEFAULT_REQUIRED_SHARE,
                sample_lines: int = 3, sample_length_m: float = 20.0, min_spacing_m: float = 0.5,
                max_confirm_pulses: int = 2_000_000, feature_cubes: int = DEFAULT_FEATURE_CUBES,
                out_dir: str | Path | None = None, client=None, workers: int | None = None,
                scheduler: str | None = None, redo: bool = False, render: bool = True,
                progress: bool = False) -> SurveyPlan:
    """The plan of least survey time meeting ``order`` over ``scene``'s site, per water (module docstring,
    docs/planning.md). ``scene``: a SceneConfig or a shipped scene's name or file; ``altitudes_m`` and
    ``speeds_m_s`` default to the scene's times :data:`DEFAULT_ALTITUDE_FACTORS` and :data:`DEFAULT_SPEED_FACTORS`.
    The passes (``sample-*``, ``confirm-*``) run into ``out_dir`` (a temporary folder when None) as Dask tasks on
    ``client``, ``scheduler`` or a local cluster of ``workers``; complete ones are kept on a re-run (unless ``redo``).
    ``feature_cubes``: cubes of the order's feature size placed in each confirmation pass, where the order asks
    feature detection (0: none, the density rule alone judges it). With ``out_dir``, the plan's files are written
    there too (:func:`~scanner_sim.studies.plan_files.write_plan_files`; ``render``: the chart and plan.html).
    Every input is checked before anything is written."""
    config = _scene_config(scene)
    k = order_index(order)
    factor = s44.ORDERS[k].coverage_percent / 100.0
    need = required_share * min(1.0, factor)
    waters, altitudes, speeds = _checked_inputs(config, waters, altitudes_m, speeds_m_s, required_share,
                                                 sample_lines, sample_length_m, min_spacing_m)
    built = cached_scene(config)
    area = site_area(config, built)
    check_reach(config, waters, altitudes, area.world([-0.5 * sample_length_m, 0.5 * sample_length_m], [0.0, 0.0]))
    half_band = half_reach_m(config, max(altitudes))
    lines = choose_sample_lines(built, area, sample_length_m, half_band, sample_lines)
    trim = max(2.0, 2.0 * s44.order_scales()[k].cell_m)  # the line's ends: the scan's run-in and whole order cells
    combos = [(w, a, v) for w in waters for a in altitudes for v in speeds]
    # line by line: the passes of one line share its scene (a raster seabed's window), which a worker then keeps from
    # one pass to the next with its BVH, instead of reading another from the cache for every pass
    jobs = [PassJob(f"sample-{w}-{a:g}m-{v:g}mps-{i + 1}", sample_config(config, w, a, v, line),
                    PassOptions(progress=False, render=False, write_scene=False))
            for i, line in enumerate(lines) for w, a, v in combos]
    from scanner_sim.io.run_dir import hold_output

    with _folder(out_dir) as out, hold_output(out), maybe_client(client, scheduler, workers, announce=progress) as dask:
        outcomes = all_ran(run_jobs(jobs, out, dask, redo=redo, progress=progress))
        profiles = []
        for j, (w, a, v) in enumerate(combos):
            parts = [profile_of(pass_grid(out / o.job.name), line, half_band, trim)
                     for o, line in zip(outcomes[j::len(combos)], lines)]
            cells, by_order, covered, gaps, soundings = (np.sum(x, axis=0) for x in zip(*parts))
            offsets = (np.arange(cells.size) + 0.5) * BIN_M - half_band
            profiles.append(Profile(w, a, v, offsets, cells, by_order[k], covered,
                                    {c: float(g) for c, g in zip(GAP_CAUSES, gaps) if g}, by_order, soundings))
        ladders = {w: ladder_candidates([p for p in profiles if p.water == w], area, factor, need, min_spacing_m)
                   for w in waters}
        # the pulses a second the scanner fires, as the first sample pass counted them over its line's time
        rate = outcomes[0].summary["pulses"] / (sample_length_m / combos[0][2])
        by_combo = {(p.water, p.altitude_m, p.speed_m_s): p for p in profiles}
        results, configs, n_confirm = confirm_plans(config, out, dask, area, ladders, by_combo, k, factor, need,
                                                    built, max_confirm_pulses, progress, redo, rate, feature_cubes)
        plans = []
        for w in waters:
            chosen, confirmation = results[w]
            if chosen is None:
                best, cause = best_order_and_cause([p for p in profiles if p.water == w], k, required_share,
                                                   min_spacing_m, area)
                cause = confirmed_cause(confirmation, need) or cause
                plans.append(WaterPlan(w, None, tuple(ladders[w]), confirmation, best, cause))
            else:
                plans.append(WaterPlan(w, chosen, tuple(ladders[w]), confirmation))
        plan = SurveyPlan(config.name, order, area, required_share,
                          tuple((tuple(map(float, a)), tuple(map(float, b))) for a, b in lines),
                          tuple(plans), tuple(profiles), len(jobs), n_confirm, config, configs)
        if out_dir is not None:
            from scanner_sim.studies.plan_files import write_plan_files

            write_plan_files(plan, out, render=render)
    return plan


def _scene_config(scene) -> SceneConfig:
    from scanner_sim.config import load_scene

    config = scene if isinstance(scene, SceneConfig) else load_scene(scene)
    if not config.has_seabed or config.seabed is None:
        raise ParameterError(f"scene '{config.name}': a plan is measured over the site's seabed; the scene has no "
                             "seabed section (a raster or a procedural seabed)")
    if config.platform.altitude_m is None:
        raise ParameterError(f"scene '{config.name}': platform.altitude_m is not set; the planner varies the altitude "
                             "above the seabed")
    return config


def _checked_inputs(config, waters, altitudes_m, speeds_m_s, required_share, sample_lines, sample_length_m,
                    min_spacing_m):
    waters = tuple(waters)
    if not waters or len(set(waters)) != len(waters):
        raise ParameterError(f"waters = {list(waters)}: give one or more distinct water presets")
    for w in waters:
        water_preset(w)
    altitudes = tuple(float(a) for a in (altitudes_m or [config.platform.altitude_m * f
                                                           for f in DEFAULT_ALTITUDE_FACTORS]))
    speeds = tuple(float(v) for v in (speeds_m_s or [config.platform.speed_m_s * f for f in DEFAULT_SPEED_FACTORS]))
    for name, values in (("altitudes_m", altitudes), ("speeds_m_s", speeds)):
        if len(set(values)) != len(values) or not all(math.isfinite(x) and x > 0 for x in values):
            raise ParameterError(f"{name} = {list(values)}: each must be a distinct finite number > 0")
    if not (isinstance(required_share, float) and 0.0 < required_share <= 1.0):
        raise ParameterError(f"required_share = {required_share!r}: must be a number in (0, 1]")
    if not (isinstance(sample_lines, int) and sample_lines >= 1):
        raise ParameterError(f"sample_lines = {sample_lines!r}: must be an integer >= 1")
    for name, value in (("sample_length_m", sample_length_m), ("min_spacing_m", min_spacing_m)):
        if not (math.isfinite(value) and value > 0):
            raise ParameterError(f"{name} = {value!r}: must be a finite number > 0 [m]")
    return waters, altitudes, speeds


class _folder:
    """``out_dir`` as a Path, created; a temporary folder, removed afterwards, when None."""

    def __init__(self, out_dir):
        self.out_dir, self._tmp = out_dir, None

    def __enter__(self) -> Path:
        if self.out_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="muls-plan-")
            return Path(self._tmp.name)
        Path(self.out_dir).mkdir(parents=True, exist_ok=True)
        return Path(self.out_dir)

    def __exit__(self, *exc):
        if self._tmp is not None:
            self._tmp.cleanup()
