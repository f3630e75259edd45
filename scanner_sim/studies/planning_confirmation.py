"""Survey planning, step 4 (:mod:`scanner_sim.studies.planning`, docs/planning.md): the least-time candidates flown
as a lawnmower over the area (or a centred sample of it), with feature cubes where the order asks feature
detection, and judged on the area's cells.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config import SceneConfig
from scanner_sim.metrics import s44
from scanner_sim.metrics.coverage import COVERED, GAP_CAUSES, NOT_REACHED
from scanner_sim.metrics.feature_cubes import with_cubes
from scanner_sim.runs.jobs import PassQueue
from scanner_sim.runs.tasks import PassJob
from scanner_sim.studies.planning_prediction import Candidate, line_count, make_candidate, survey_time_s
from scanner_sim.studies.planning_sampling import SiteArea, all_ran, flown_config, pass_grid
from scanner_sim.survey.feature_placement import cube_positions
from scanner_sim.survey.setup import PassOptions

#: Cubes of the order's feature size placed in a confirmation, by default: 19 of 20 detected is the 95 % share.
DEFAULT_FEATURE_CUBES = 20


#: Fewest cubes a confirmation places.
MIN_FEATURE_CUBES = 5


#: Seed of the cubes' positions.
CUBE_SEED = 0


#: Confirmations tried per water (each a pass over the area) before the water is declared not achievable.
MAX_CONFIRMATIONS = 3


#: Steps of one line fewer tried below a confirmed plan, per water.
MAX_DESCENT = 6


def duration(seconds: float) -> str:
    """A survey time in words: minutes below two hours, else hours."""
    return f"{seconds / 60:.1f} min" if seconds < 7200 else f"{seconds / 3600:.2f} h"


def plan_config(config, water, area: SiteArea, candidate: Candidate) -> SceneConfig:
    """The lawnmower of ``candidate`` over ``area`` in ``water``."""
    return flown_config(config, water, candidate.altitude_m, candidate.speed_m_s,
                        {"mode": "lawnmower", "waypoints_m": None,
                         "lawnmower": {"center_m": list(area.center_m), "size_m": list(area.size_m),
                                       "heading_deg": area.heading_deg, "line_spacing_m": candidate.spacing_m}})


def confirm_area(area: SiteArea, candidate: Candidate, pulse_rate_hz: float, max_pulses: int) -> SiteArea:
    """The area the confirmation flies: the whole ``area`` when its pulses fit ``max_pulses``, else a centred sample:
    the lines cut shorter, then fewer lines (at least 3), until they fit."""
    def pulses(a: SiteArea) -> float:
        return survey_time_s(a, candidate.spacing_m, candidate.speed_m_s) * pulse_rate_hz

    if pulses(area) <= max_pulses:
        return area
    length, width = area.size_m
    n = line_count(width, candidate.spacing_m)
    short = max(20.0, length * max_pulses / pulses(area))
    while n > 3 and (n * short + (n - 1) * candidate.spacing_m) / candidate.speed_m_s * pulse_rate_hz > max_pulses:
        n -= 1
    return replace(area, size_m=(min(length, short), min(width, (n - 1) * candidate.spacing_m)))


def area_cells(grid: dict, area: SiteArea, spacing_m: float, scene) -> np.ndarray:
    """(ny, nx) bool: the coverage grid's cells (``grid``: coverage_grid.npz's arrays) whose centre lies in the
    planned area (the area's lines with half a spacing either side, within the area) and has seabed data."""
    ny, nx = grid["state"].shape
    cell, (x0, y0) = float(grid["cell_m"]), grid["origin_m"]
    gx, gy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * cell, y0 + (np.arange(ny) + 0.5) * cell)
    along, left = area.local(np.c_[gx.ravel(), gy.ravel()])
    n = line_count(area.size_m[1], spacing_m)
    half_across = min(0.5 * area.size_m[1], 0.5 * (n - 1) * spacing_m + 0.5 * spacing_m)
    inside = (np.abs(along) <= 0.5 * area.size_m[0]) & (np.abs(left) <= half_across)
    return (inside & scene.heightfield.covers(gx.ravel(), gy.ravel())).reshape(ny, nx)


def judged(grid: dict, cells: np.ndarray, k: int) -> dict:
    """Compliance with order index ``k`` (or a stricter one) and coverage over ``cells``: shares and gap causes."""
    n = int(cells.sum())
    order = grid["s44_order"][cells]
    state = grid["state"][cells]
    area = float(grid["cell_m"]) ** 2
    gaps = np.bincount(state[state >= 0].astype(int), minlength=len(GAP_CAUSES)) * area
    return {"cells": n, "area_m2": n * area,
            "compliant_share": float(((order >= 0) & (order <= k)).sum() / n) if n else 0.0,
            "covered_share": float((state == COVERED).sum() / n) if n else 0.0,
            "not_reached_share": float((state == NOT_REACHED).sum() / n) if n else 0.0,
            "gaps_m2": {c: float(g) for c, g in zip(GAP_CAUSES, gaps) if g}}


def confirm_plans(config, out: Path, dask, area, ladders, profiles, k, factor, need, built, max_pulses, progress,
                  redo, rate, cubes):
    """Per water: confirm the cheapest feasible candidate by a pass, on a shortfall the next (up to
    MAX_CONFIRMATIONS); once one is confirmed, confirm the plan of one line fewer at its altitude and speed, and
    while that meets the order too, take it and go one line fewer again (the prediction errs on the safe side), up to
    MAX_DESCENT. Each water's confirmations are a chain of their own: its next pass is handed in as soon as its last
    is judged, while the other waters' passes run (:class:`~scanner_sim.runs.jobs.PassQueue`), so the result does not
    depend on which finishes first. ``rate``: the pulses a second the passes fire [Hz]; ``cubes``: feature cubes placed
    in each confirmation of an order that asks feature detection (:func:`_cubes`). Returns per water (chosen,
    confirmation), the chosen plans' confirmation configs by water, and the passes run."""
    results: dict = {w: (None, None) for w in ladders}
    configs: dict = {}
    mode = {w: "search" for w in ladders}
    steps = {w: 0 for w in ladders}
    chosen_at: dict = {}
    queue = PassQueue(out, dask, redo=redo, progress=progress)

    def hand_in(w) -> None:
        """Put water w's next confirmation in the queue, or mark the water done."""
        cands = ladders[w]
        if mode[w] == "search":
            feasible = [i for i, c in enumerate(cands) if c.status == "feasible"]
            if not feasible or steps[w] >= MAX_CONFIRMATIONS:
                mode[w] = "done"
                return
            i = feasible[0]
        elif mode[w] == "descend":
            c = cands[chosen_at[w]]
            if c.lines <= 2 or steps[w] >= MAX_DESCENT:
                mode[w] = "done"
                return
            spacing = area.size_m[1] / (c.lines - 2)
            same = [j for j, d in enumerate(cands) if (d.altitude_m, d.speed_m_s, d.lines)
                    == (c.altitude_m, c.speed_m_s, c.lines - 1)]
            if same:
                i = same[0]
            else:
                cands.append(make_candidate(profiles[w, c.altitude_m, c.speed_m_s], area, spacing, factor, need))
                i = len(cands) - 1
        else:
            return
        c = cands[i]
        flown = confirm_area(area, c, rate, max_pulses)
        cfg = plan_config(config, w, flown, c).with_overrides({"output.las": True})
        placed = _cubes(cfg, k, cubes)
        if placed:
            cfg = with_cubes(cfg, placed)
        queue.put(PassJob(f"confirm-{w}-{c.altitude_m:g}m-{c.speed_m_s:g}mps-{c.spacing_m:g}m", cfg,
                          PassOptions(progress=False, render=False, write_scene=False)), (w, i, flown, placed))

    for w in ladders:
        hand_in(w)
    taken = []
    for (w, i, flown, placed), outcome in queue.finished():
        taken.append(outcome)
        if outcome.status == "failed":  # the passes under way finish and are kept; none is handed in after it
            mode.update(dict.fromkeys(mode, "done"))
            continue
        job = outcome.job
        steps[w] += 1
        c = ladders[w][i]
        grid = pass_grid(out / job.name)
        reading = judged(grid, area_cells(grid, flown, c.spacing_m, built), k)
        detection = _detection(outcome.summary, placed)
        met = (reading["compliant_share"] >= need and reading["covered_share"] >= need
               and (detection is None or detection["detected_share"] >= need))
        confirmation = {"pass": job.name, "whole_area": flown == area,
                        "area": {"center_m": list(flown.center_m), "size_m": list(flown.size_m)},
                        "pulses": outcome.summary["pulses"], "met": met, **reading, "features": detection}
        short = (f"compliance {100 * reading['compliant_share']:.1f} %, coverage "
                 f"{100 * reading['covered_share']:.1f} %"
                 + (f", features detected {detection['detected']} of {detection['placed']}" if detection else "")
                 + f" (need {100 * need:g} %)")
        if met:
            if w in chosen_at:  # the one before, a line more, met too: costlier
                before = ladders[w][chosen_at[w]]
                ladders[w][chosen_at[w]] = replace(before, status="rejected", reason=(
                    f"costlier than the chosen plan, one line fewer, which also met the order "
                    f"({duration(before.survey_time_s)} against {duration(c.survey_time_s)})"))
            how = ("confirmed a line fewer than a confirmed plan (the prediction erred safe)" if w in chosen_at
                   else "the least-time candidate predicted to meet the order, confirmed")
            ladders[w][i] = replace(c, status="chosen", reason=f"chosen: {how}; one line fewer confirmed short or "
                                    "not possible", confirmed=confirmation)
            results[w], configs[w], chosen_at[w] = (ladders[w][i], confirmation), job.config, i
            if mode[w] == "search":
                mode[w], steps[w] = "descend", 0
        else:
            prefix = "one line fewer than the chosen plan: " if mode[w] == "descend" else ""
            ladders[w][i] = replace(c, status="rejected", reason=f"{prefix}confirmed short: {short}",
                                    confirmed=confirmation)
            if mode[w] == "descend":
                mode[w] = "done"
            else:
                results[w] = (None, confirmation)
        hand_in(w)
    queue.close()
    all_ran(taken)
    configs = {w: configs[w] for w in ladders if w in configs}  # in the waters' order, whichever finished first
    for w, cands in ladders.items():
        chosen = results[w][0]
        for i, c in enumerate(cands):
            if c.status == "feasible":
                cands[i] = replace(c, status="rejected", reason=(
                    f"costlier than the chosen plan ({duration(c.survey_time_s)} against "
                    f"{duration(chosen.survey_time_s)})" if chosen else f"not confirmed: {MAX_CONFIRMATIONS} "
                    "cheaper candidates were confirmed short first"))
        cands.sort(key=lambda c: (c.status != "chosen", c.survey_time_s, c.altitude_m, c.speed_m_s))
    return results, configs, len(taken)


def _cubes(config: SceneConfig, k: int, count: int) -> list[dict]:
    """``count`` cubes of order k's feature size placed across the swath of ``config``'s pass (half as many while they
    do not fit apart and in view, down to MIN_FEATURE_CUBES), or none when the order asks no feature detection, or
    when not even that many fit (then the density rule alone judges detection)."""
    size = s44.ORDERS[k].feature_m
    while size is not None and count >= MIN_FEATURE_CUBES:
        try:
            return cube_positions(config, [size], count, CUBE_SEED, None, "feature_cubes")
        except ParameterError:  # no room for them apart and in view: half as many
            count //= 2
    return []


def _detection(summary: dict, placed: list[dict]) -> dict | None:
    """The cubes ``placed`` in a confirmation: placed, detected (>= s44.FEATURE_MIN_SOUNDINGS valid soundings on
    it), their share, and the not-detected ones' causes; None without cubes."""
    if not placed:
        return None
    names = {p["name"] for p in placed}
    mine = [o for o in summary["coverage"]["objects"] if o["name"] in names]
    detected = sum(o["detected"] for o in mine)
    causes: dict = {}
    for o in mine:
        if not o["detected"]:
            causes[o["gap_cause"]] = causes.get(o["gap_cause"], 0) + 1
    return {"size_m": placed[0]["size_m"], "placed": len(placed), "detected": detected,
            "detected_share": detected / len(placed), "missed_by_cause": causes}


def confirmed_cause(confirmation: dict | None, need: float) -> str | None:
    """What failed the last confirmation of a water that meets no plan: its undetected cubes and their causes when
    detection fell short, else its gap cause with the most area; None without a confirmation (or a gap)."""
    if confirmation is None:
        return None
    f = confirmation.get("features")
    if f and f["detected_share"] < need:
        causes = ", ".join(f"{c} {n}" for c, n in sorted(f["missed_by_cause"].items(), key=lambda item: -item[1]))
        return (f"feature detection: {f['detected']} of {f['placed']} {f['size_m']:g} m cubes detected in the "
                f"confirmation {confirmation['pass']} (missed: {causes})")
    gaps = confirmation["gaps_m2"]
    if gaps:
        cause = max(gaps, key=gaps.get)
        return f"{cause} ({gaps[cause]:.0f} m² of the confirmation {confirmation['pass']}'s planned area)"
    return None
