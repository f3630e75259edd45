"""The survey planner's reading matter: plan.md (a table per water) and plan.html (one self-contained page with the
chart and the tables), both from plan.json's content (docs/planning.md)."""

from __future__ import annotations

import html
from pathlib import Path

from scanner_sim.render.report import _STYLE, _image, html_table, markdown_table

CANDIDATE_HEADER = ["altitude [m]", "speed [m/s]", "spacing [m]", "lines", "swath [m]", "predicted", "confirmed",
                    "survey time [min]", "status", "why"]


def _pct(x) -> str:
    """A share as a percentage; two decimals above 99.9 %, so that 99.97 % does not read as a full 100.0 %."""
    if x is None:
        return "—"
    return f"{100 * x:.2f} %" if 0.999 < x < 1.0 else f"{100 * x:.1f} %"


def candidate_rows(water: dict) -> list[list[str]]:
    return [[f"{c['altitude_m']:g}", f"{c['speed_m_s']:g}", f"{c['spacing_m']:.2f}", str(c["lines"]),
             f"{c['swath_m']:g}", _pct(c["predicted_share"]),
             _pct(c["confirmed"]["compliant_share"]) if c["confirmed"] else "—", f"{c['survey_time_s'] / 60:.1f}",
             c["status"], c["reason"]] for c in water["candidates"]]


def water_summary(plan: dict, water: dict) -> str:
    """One sentence: the chosen plan and its confirmation, or why the water cannot meet the order."""
    c = water["chosen"]
    if c is None:
        return (f"{water['water']}: {plan['order']} order not achievable with the altitudes and speeds tried; best "
                f"order predicted: {water['best_order'] or 'none'}; limiting cause: {water['limiting_cause']}.")
    conf = water["confirmation"]
    size = conf["area"]["size_m"]
    where = "the whole area" if conf["whole_area"] else f"a {size[0]:g} x {size[1]:g} m sample"
    return (f"{water['water']}: {c['altitude_m']:g} m altitude, {c['speed_m_s']:g} m/s, {c['lines']} lines "
            f"{c['spacing_m']:.2f} m apart ({c['line_length_m']:.0f} m of line), {c['survey_time_s'] / 60:.1f} min; "
            f"predicted {_pct(c['predicted_share'])}, confirmed over {where}: compliance "
            f"{_pct(conf['compliant_share'])}, coverage {_pct(conf['covered_share'])}.")


def _intro(plan: dict) -> str:
    a = plan["area"]
    return (f"Scene {plan['scene']}: IHO S-44 {plan['order']} order on at least {100 * plan['required_share']:g} % "
            f"of the planned area; survey area {a['size_m'][0]:.0f} x {a['size_m'][1]:.0f} m, lines heading "
            f"{a['heading_deg']:g}°; {plan['sample_passes']} sample passes over {len(plan['sample_lines_m'])} "
            f"sample lines, {plan['confirmation_passes']} confirmation passes.")


def plan_markdown(plan: dict) -> str:
    parts = [f"# Survey plan: {plan['scene']}, {plan['order']} order\n", _intro(plan) + "\n"]
    for water in plan["waters"]:
        parts += [f"## {water['water']}\n", water_summary(plan, water) + "\n",
                  markdown_table(CANDIDATE_HEADER, candidate_rows(water))]
    return "\n".join(parts)


def plan_html(plan: dict, out_dir: str | Path) -> str:
    """plan.html: the chart (plan_chart.png from ``out_dir``, embedded) and a table of candidates per water."""
    title = f"Survey plan: {plan['scene']}, {plan['order']} order"
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
             f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1><p>{html.escape(_intro(plan))}</p>"]
    chart = Path(out_dir) / "plan_chart.png"
    if chart.exists():
        parts.append(f"<figure>{_image(chart, 'survey time against compliance')}<figcaption>survey time against "
                     "predicted compliance per water; the star is the chosen plan, the cross its confirmation"
                     "</figcaption></figure>")
    for water in plan["waters"]:
        parts += [f"<h2>{html.escape(water['water'])}</h2><p>{html.escape(water_summary(plan, water))}</p>",
                  html_table(CANDIDATE_HEADER, candidate_rows(water))]
    parts.append("</body></html>\n")
    return "".join(parts)
