"""The coverage study's reading matter: coverage.md (tables) and report.html (one self-contained page).

Both take the study as written to coverage.json (:func:`scanner_sim.studies.coverage_study.run_study`); the tables
are built once as rows of text and rendered to Markdown and to HTML. The page embeds every picture as a
base64 data URI, so it can be mailed or archived as one file.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path

#: Pictures of one combination shown in the report, with their captions.
COMBINATION_PICTURES = (("coverage_map.png", "coverage map"), ("render.png", "point cloud"))


def _percent(x) -> str:
    return "–" if x is None else f"{100.0 * x:.1f}"


def _altitude(altitude_m) -> str:
    return "–" if altitude_m is None else f"{altitude_m:g}"


def _gaps(gaps: dict, unit: str) -> str:
    parts = [f"{cause.replace('_', ' ')} {amount:.2f}" for cause, amount in
             sorted(gaps.items(), key=lambda kv: -kv[1]) if amount > 0]
    return ", ".join(parts) + f" {unit}" if parts else "none"


def main_table(study: dict) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the coverage table, one row per combination."""
    header = ["water", "instrument", "altitude [m]", "covered [%]", "reached [m²]", "valid points [1/m²]",
              "holes (largest [m²])", "gaps by cause", "cable covered [%]", "objects detected", "points / pulses"]
    rows = []
    for r in study["records"]:
        cables = "; ".join(f"{c['name']} {_percent(c['covered_fraction'])}" for c in r["cables"]) or "–"
        objects = r["objects"]
        detected = f"{sum(o['detected'] for o in objects)}/{len(objects)}" if objects else "–"
        rows.append([
            r["water"], r["instrument"], _altitude(r["altitude_m"]),
            _percent(r["covered_fraction"]), f"{r['reached_area_m2']:.1f}",
            "–" if r["density_pts_per_m2"] is None else f"{r['density_pts_per_m2']:.0f}",
            f"{r['holes']['count']} ({r['holes']['largest_m2']:.2f})", _gaps(r["gaps_m2"], "m²"), cables, detected,
            f"{r['points']:,} / {r['pulses']:,}",
        ])
    return header, rows


def object_table(study: dict) -> tuple[list[str], list[list[str]]]:
    """Header and rows per combination and object (mines, panels, meshes) and per cable."""
    header = ["water", "instrument", "altitude [m]", "object", "reaching pulses", "valid points", "result"]
    rows = []
    for r in study["records"]:
        key = [r["water"], r["instrument"], _altitude(r["altitude_m"])]
        for o in r["objects"]:
            result = "detected" if o["detected"] else (f"missed: {o['gap_cause'].replace('_', ' ')}"
                                                       if o["gap_cause"] else "not reached")
            rows.append(key + [f"{o['name']} ({o['kind']})", f"{o['reaching_pulses']:,}", f"{o['valid_points']:,}",
                               result])
        for c in r["cables"]:
            rows.append(key + [f"{c['name']} (cable, {c['length_m']:.1f} m)", "–", f"{c['valid_points']:,}",
                               f"{c['covered_m']:.1f} of {c['reached_m']:.1f} m reached covered; gaps: "
                               f"{_gaps(c['gaps_m'], 'm')}"])
    return header, rows


def multichannel_table(study: dict) -> tuple[list[str], list[list[str]]] | None:
    """mul2023 against single_channel at each water and altitude, when the study has both."""
    by_key = {(r["water"], r["altitude_m"], r["instrument"]): r for r in study["records"]}
    pairs = [(w, a) for (w, a, i) in by_key if i == "mul2023" and (w, a, "single_channel") in by_key]
    if not pairs:
        return None
    header = ["water", "altitude [m]", "mul2023 covered [%]", "single_channel covered [%]", "difference [points]"]
    rows = []
    for w, a in pairs:
        m, s = by_key[(w, a, "mul2023")], by_key[(w, a, "single_channel")]
        rows.append([w, _altitude(a), _percent(m["covered_fraction"]),
                     _percent(s["covered_fraction"]), f"{m['valid_points_in_reach'] - s['valid_points_in_reach']:+,}"])
    return header, rows


def markdown_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def html_table(header, rows) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _definitions(study: dict) -> str:
    s = study["study"]
    return (f"A plan cell of {s['cell_m']:g} m is *reached* when at least {s['min_points']} pulse(s) of the nominal "
            f"scan pattern meet a surface in it, and *covered* when it also holds at least {s['min_points']} "
            f"point(s) whose range error is within ±{s['tolerance_m']:g} m. Covered % is of the reached area. "
            "Points count in the cell of the seabed they measured (their pulse's nominal footprint). A missed cell, "
            "cable stretch or object takes the cause that failed most of the pulses reaching it; `other surface` "
            "means those pulses gave valid points from another surface. Gate: " + s["gate"] + ".")


def _sections(study: dict):
    """(title, table) pairs shared by the Markdown and the HTML."""
    sections = [("Coverage", main_table(study))]
    multi = multichannel_table(study)
    if multi:
        sections.append(("Multi-channel against single channel", multi))
    objects = object_table(study)
    if objects[1]:
        sections.append(("Objects and cables", objects))
    return sections


def coverage_markdown(study: dict) -> str:
    """coverage.md: the tables a person reads."""
    parts = [f"# Coverage study: {study['scene']}\n", _definitions(study) + "\n"]
    for title, (header, rows) in _sections(study):
        parts.append(f"## {title}\n\n" + markdown_table(header, rows))
    parts.append(f"Study time {study['wall_s']:.0f} s.\n")
    return "\n".join(parts)


def _image(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #1b1b1b; max-width: 1500px; }
table { border-collapse: collapse; font-size: 0.85em; margin-bottom: 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: left; vertical-align: top; }
th { background: #eef2f5; }
figure { display: inline-block; margin: 0.5em 1em 0.5em 0; vertical-align: top; }
figure img { max-width: 720px; width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; }
"""


#: Where ``scanner-sim tradeoff`` writes by default (the scene's output.dir + /tradeoff), from the study's folder
#: (the scene's output.dir + /coverage).
TRADEOFF_DIR = "../tradeoff"


def tradeoff_section(study: dict, out: Path) -> str:
    """The page's pointer to the speed-against-accuracy chart of the scene's fidelity levels: the chart itself,
    embedded, when ``scanner-sim tradeoff`` has written it beside the study, else the command that writes it."""
    scene = html.escape(str(study["scene"]))
    chart = out / TRADEOFF_DIR / "tradeoff.png"
    text = (f"<h2>Speed against accuracy</h2><p>How far each fidelity level lies from the truth and from the "
            f"reference level, against its speed: <code>scanner-sim tradeoff {scene}</code> writes tradeoff.png, "
            f"tradeoff.md and tradeoff.json in {html.escape(TRADEOFF_DIR)}/ from this folder.</p>")
    if chart.exists():
        text += f"<figure>{_image(chart, 'speed against accuracy')}<figcaption>speed against accuracy</figcaption></figure>"
    return text


def report_html(study: dict, out_dir: str | Path) -> str:
    """report.html: the tables, the coverage-against-altitude chart, and per combination its coverage map and
    rendered point cloud, every picture embedded. Pictures are read from ``out_dir`` as run_study writes them."""
    out = Path(out_dir)
    title = f"Coverage study: {study['scene']}"
    parts = [f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
             f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1>",
             f"<p>{html.escape(_definitions(study)).replace('*', '')}</p>"]
    chart = out / "coverage_vs_altitude.png"
    if chart.exists():
        parts.append(f"<figure>{_image(chart, 'coverage against altitude')}"
                     "<figcaption>coverage against altitude</figcaption></figure>")
    for heading, (header, rows) in _sections(study):
        parts.append(f"<h2>{html.escape(heading)}</h2>" + html_table(header, rows))
    parts.append(tradeoff_section(study, out))
    parts.append("<h2>Maps and point clouds</h2>")
    for r in study["records"]:
        parts.append(f"<h3>{html.escape(r['dir'])}</h3>")
        for file, caption in COMBINATION_PICTURES:
            picture = out / r["dir"] / file
            if picture.exists():
                parts.append(f"<figure>{_image(picture, caption + ' ' + r['dir'])}"
                             f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
