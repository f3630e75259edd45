"""Survey planning, step 3 (:mod:`scanner_sim.studies.planning`, docs/planning.md): from the profiles the sample
passes measured, each altitude and speed's line spacings predicted to meet the order, and their survey times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scanner_sim.metrics import s44
from scanner_sim.studies.planning_sampling import BIN_M, Profile, SiteArea


def predicted_share(profile: Profile, spacing_m: float, coverage_factor: float) -> float:
    """Share of the planned area predicted to comply with lines ``spacing_m`` apart. A cell lies at offset d from its
    nearest line, d uniform over [-s/2, s/2], and at d + j s from the others; its soundings come from every line whose
    scan reaches it, as many from each as the profile's cells at that offset hold, and a line's soundings at an
    offset are taken to be good with that offset's compliant share. The cell's prediction is that share weighted by
    the soundings of each line (a far line's many poor soundings spoil a cell its near line alone would make comply).
    At 200 % coverage a cell a second line does not reach counts as failing."""
    d = (np.arange(max(1, round(spacing_m / BIN_M))) + 0.5) * BIN_M - 0.5 * spacing_m
    reach = np.abs(profile.offset_m).max()
    good, soundings = np.zeros(d.size), np.zeros(d.size)
    lines = np.zeros(d.size, int)
    for j in range(-int(reach // spacing_m) - 1, int(reach // spacing_m) + 2):
        offset = d + j * spacing_m
        n = profile.soundings_at(offset)
        good += n * profile.share(offset)
        soundings += n
        lines += n > 0
    share = np.where(soundings > 0, good / np.maximum(soundings, 1e-12), 0.0)
    if coverage_factor > 1.0:
        share = np.where(lines >= 2, share, 0.0)
    return float(share.mean())


def line_count(width_m: float, spacing_m: float) -> int:
    """Lines of a lawnmower ``width_m`` across at ``spacing_m`` (as :func:`lawnmower_waypoints` lays them)."""
    return int(math.floor(width_m / spacing_m + 1e-9)) + 1


def survey_time_s(area: SiteArea, spacing_m: float, speed_m_s: float) -> float:
    """Vehicle time [s] of the lawnmower: every line's length plus a turn between lines, the turn being the leg
    across to the next line (``spacing_m``) flown at the survey speed, as the pass flies it (corners rounded)."""
    n = line_count(area.size_m[1], spacing_m)
    return (n * area.size_m[0] + (n - 1) * spacing_m) / speed_m_s


@dataclass(frozen=True)
class Candidate:
    """One plan tried: altitude [m], speed [m/s], line spacing [m], its measured swath [m], predicted compliant share,
    survey time [s], line length [m] (all lines), and ``status`` (chosen, rejected) with ``reason``."""

    altitude_m: float
    speed_m_s: float
    spacing_m: float
    swath_m: float
    predicted_share: float
    survey_time_s: float
    line_length_m: float
    lines: int
    status: str = "rejected"
    reason: str = ""
    confirmed: dict | None = None

    def as_json(self) -> dict:
        return {"altitude_m": self.altitude_m, "speed_m_s": self.speed_m_s, "spacing_m": round(self.spacing_m, 4),
                "swath_m": self.swath_m, "predicted_share": round(self.predicted_share, 4),
                "survey_time_s": round(self.survey_time_s, 1), "survey_time_h": round(self.survey_time_s / 3600, 3),
                "line_length_m": round(self.line_length_m, 1), "lines": self.lines, "status": self.status,
                "reason": self.reason, "confirmed": self.confirmed}


def spacing_ladder(width_m: float, min_spacing_m: float) -> np.ndarray:
    """Spacings tried, ascending [m]: width / (n - 1) for n lines spanning the area's width exactly,
    from the most lines with a spacing of at least ``min_spacing_m`` down to two: each step one line fewer, so each
    wider spacing is a cheaper plan."""
    most = max(2, int(math.floor(width_m / min_spacing_m + 1e-9)) + 1)
    return np.array([width_m / (n - 1) for n in range(most, 1, -1)])


def ladder_candidates(profiles, area: SiteArea, factor: float, need: float, step: float) -> list[Candidate]:
    """Per altitude x speed, the widest spacing on the ladder (:func:`spacing_ladder`) whose prediction holds ``need``
    (or, if none does, the narrowest, rejected) and the next wider one, a line fewer (rejected), sorted by time."""
    out = []
    ladder = spacing_ladder(area.size_m[1], step)
    for p in profiles:
        swath = p.swath_m(need)
        shares = np.array([predicted_share(p, s, factor) for s in ladder])
        ok = shares >= need
        last = int(np.flatnonzero(ok)[-1]) if ok.any() else -1

        def cand(i: int, reason: str, status: str = "rejected", p=p, swath=swath, shares=shares) -> Candidate:
            s = float(ladder[i])
            n = line_count(area.size_m[1], s)
            return Candidate(p.altitude_m, p.speed_m_s, s, swath, float(shares[i]),
                             survey_time_s(area, s, p.speed_m_s), n * area.size_m[0], n, status, reason)

        if last < 0:
            best = int(np.argmax(shares))
            out.append(cand(best, f"predicted compliance at most {100 * shares[best]:.1f} % < {100 * need:g} % at any "
                                  f"spacing of at least {ladder[0]:.2f} m"))
            continue
        out.append(cand(last, "", "feasible"))
        if last + 1 < ladder.size:
            out.append(cand(last + 1, "next wider spacing (one line fewer): predicted compliance "
                                      f"{100 * shares[last + 1]:.1f} % < {100 * need:g} %"))
    return sorted(out, key=lambda c: (c.status != "feasible", c.survey_time_s, c.altitude_m, c.speed_m_s))


def make_candidate(p: Profile, area: SiteArea, spacing_m: float, factor: float, need: float) -> Candidate:
    """The candidate of profile ``p``'s altitude and speed at ``spacing_m`` over ``area``, with its prediction."""
    n = line_count(area.size_m[1], spacing_m)
    return Candidate(p.altitude_m, p.speed_m_s, spacing_m, p.swath_m(need),
                     predicted_share(p, spacing_m, factor), survey_time_s(area, spacing_m, p.speed_m_s),
                     n * area.size_m[0], n)


def best_order_and_cause(profiles, k, required, step, area) -> tuple[str | None, str]:
    """The strictest order the sample passes predict some altitude and speed meets, and what limits the asked one:
    the gap cause with most area in the sample passes, or, without gaps, soundings that miss the order's limits."""
    best = None
    for j in range(k + 1, len(s44.ORDERS)):
        f = s44.ORDERS[j].coverage_percent / 100.0
        need = required * min(1.0, f)
        ladder = spacing_ladder(area.size_m[1], step)
        if any(predicted_share(p.for_order(j), s, f) >= need for p in profiles for s in ladder):
            best = s44.ORDERS[j].name
            break
    gaps: dict = {}
    for p in profiles:
        for c, g in p.gaps_m2.items():
            gaps[c] = gaps.get(c, 0.0) + g
    if gaps:
        cause = max(gaps, key=gaps.get)
        return best, f"{cause} ({gaps[cause]:.0f} m² of the sample passes' gaps, of {sum(gaps.values()):.0f} m²)"
    return best, "covered cells whose soundings miss the order's TVU/THU or sample density"
