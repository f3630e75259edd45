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
COMBINATION_PICTURES = (("coverage_map.png", "coverage map"), ("s44_map.png", "S-44 orders"),
                        ("calibration.png", "TPU calibration"), ("render.png", "point cloud"))
#: Below this covered fraction the report says in words why a combination maps (next to) nothing.
NEAR_ZERO = 0.10
#: What each gap cause means for a planner, in a sentence (the rules: docs/outputs.md, Dropout causes).
CAUSE_MEANINGS = {
    "no_hit": "the beam met nothing within the record's range",
    "blind_zone": "the target was too close: the beam and the receiver's field of view do not overlap yet",
    "saturated": "the echo clipped the detector and the clipped returns were dropped",
    "masked_by_backscatter": "the water column's own backscatter hid the echo: the water is too turbid for the "
                             "instrument at this range",
    "outside_gate": "the echo came while the far channel's gate was shut",
    "below_threshold": "the echo came back too weak to clear the detector's noise: too much water between the "
                       "lidar and the seabed for this water's attenuation",
    "out_of_tolerance": "points came back but ranged further off the truth than the tolerance (in murky water, "
                        "multiply scattered light ranges them long)",
    "other_surface": "the pulses aimed there gave valid points from another surface",
}


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
    header = ["water", "instrument", "altitude [m]", "covered [%]", "of the planned swath [%]", "reached [m²]",
              "valid points [1/m²]", "holes (largest [m²])", "gaps by cause", "cable covered [%]", "objects detected",
              "points / pulses"]
    rows = []
    for r in study["records"]:
        cables = "; ".join(f"{c['name']} {_percent(c['covered_fraction'])}" for c in r["cables"]) or "–"
        objects = r["objects"]
        detected = f"{sum(o['detected'] for o in objects)}/{len(objects)}" if objects else "–"
        rows.append([
            r["water"], r["instrument"], _altitude(r["altitude_m"]),
            _percent(r["covered_fraction"]), _percent((r.get("planned_swath") or {}).get("covered_fraction")),
            f"{r['reached_area_m2']:.1f}",
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


MULTICHANNEL_TITLE = "Multi-channel against single channel"


def _multichannel_pairs(study: dict) -> list[tuple[dict, dict]]:
    """(mul2023, single_channel) records at each water and altitude where the study has both."""
    by_key = {(r["water"], r["altitude_m"], r["instrument"]): r for r in study["records"]}
    return [(r, by_key[(w, a, "single_channel")]) for (w, a, i), r in by_key.items()
            if i == "mul2023" and (w, a, "single_channel") in by_key]


def _masked_share(record: dict) -> float | None:
    """The share of the reached area whose gap is ``masked_by_backscatter``."""
    reached = record["reached_area_m2"]
    return record["gaps_m2"]["masked_by_backscatter"] / reached if reached else None


def multichannel_table(study: dict) -> tuple[list[str], list[list[str]]] | None:
    """mul2023 against single_channel at each water and altitude, when the study has both: covered shares, their
    difference in percentage points, the difference in valid points, and the share masked by backscatter."""
    pairs = _multichannel_pairs(study)
    if not pairs:
        return None
    header = ["water", "altitude [m]", "mul2023 covered [%]", "single_channel covered [%]",
              "covered, mul2023 − single_channel [percentage points]", "valid points, mul2023 − single_channel",
              "masked by backscatter, mul2023 / single_channel [% of reached]"]
    rows = []
    for m, s in pairs:
        difference = (None if m["covered_fraction"] is None or s["covered_fraction"] is None
                      else 100 * (m["covered_fraction"] - s["covered_fraction"]))
        rows.append([m["water"], _altitude(m["altitude_m"]), _percent(m["covered_fraction"]),
                     _percent(s["covered_fraction"]), "–" if difference is None else f"{difference:+.1f}",
                     f"{m['valid_points_in_reach'] - s['valid_points_in_reach']:+,}",
                     f"{_percent(_masked_share(m))} / {_percent(_masked_share(s))}"])
    return header, rows


def multichannel_notes(study: dict) -> list[str]:
    """One sentence per water and altitude where mul2023 covers less than single_channel: the shares masked by
    backscatter and single_channel's own largest loss, and why the two instruments differ there."""
    notes = []
    for m, s in _multichannel_pairs(study):
        if m["covered_fraction"] is None or s["covered_fraction"] is None or \
                m["covered_fraction"] >= s["covered_fraction"]:
            continue
        cause, area = max(s["gaps_m2"].items(), key=lambda kv: kv[1])
        own = (f"; single_channel loses {_percent(area / s['reached_area_m2'])} % to {cause.replace('_', ' ')}"
               if area > 0 else "")
        notes.append(f"{m['water']} at {_altitude(m['altitude_m'])} m: mul2023 covers {_percent(m['covered_fraction'])} "
                     f"% against single_channel's {_percent(s['covered_fraction'])} % because the water column's "
                     f"backscatter masks the echo on {_percent(_masked_share(m))} % of mul2023's reached area against "
                     f"{_percent(_masked_share(s))} % of single_channel's{own}. mul2023 runs the pond's gains (2000 and "
                     "20,000), so the turbid column's own light clips its channels, or rises as high as the echo, over "
                     "the echo; single_channel's gain is set to keep the column unclipped, so it sees those echoes, "
                     "and loses only those too weak to clear its noise.")
    return notes


def orders_table(study: dict) -> tuple[list[str], list[list[str]]]:
    """The S-44 orders the study used (coverage.json's ``s44_orders``)."""
    header = ["order", "TVU a [m]", "TVU b", "THU [m]", "THU [% of depth]", "feature [m]", "coverage [%]"]
    rows = [[name, f"{o['tvu_a_m']:g}", f"{o['tvu_b']:g}", f"{o['thu_m']:g}", f"{100 * o['thu_depth_fraction']:g}",
             "not specified" if o["feature_m"] is None else f"> {o['feature_m']:g}", f"{o['coverage_percent']:g}"]
            for name, o in study.get("s44_orders", {}).items()]
    return header, rows


def compliance_table(study: dict) -> tuple[list[str], list[list[str]]]:
    """Per combination: the share of the surveyed area complying with each S-44 order, the share of the planned
    swath the scan reached, and the range error's signed bias beside its absolute size."""
    names = list(study.get("s44_orders", {}))
    cells = {n: o.get("cell_m") for r in study["records"] for n, o in r.get("orders", {}).items()}
    header = (["water", "instrument", "altitude [m]", "swath reached [%]"]
              + [f"{n} [%]" if cells.get(n) is None else f"{n} [%] ({cells[n]:g} m cells)" for n in names]
              + ["range error: median absolute / median signed [cm]", "points short [%]"])
    rows = []
    for r in study["records"]:
        swath = r.get("planned_swath") or {}
        error = r["range_error_m"]
        signed = error.get("median_signed")
        rows.append([r["water"], r["instrument"], _altitude(r["altitude_m"]), _percent(swath.get("reached_fraction"))]
                    + [_percent(r.get("orders", {}).get(n, {}).get("compliant_fraction")) for n in names]
                    + ["–" if error["median"] is None else f"{100 * error['median']:.1f} / {100 * signed:+.1f}",
                       _percent(error.get("share_short"))])
    return header, rows


def tpu_table(study: dict) -> tuple[list[str], list[list[str]]] | None:
    """Per combination, the predicted 95 % THU and TVU and the share of points whose true error they hold."""
    if not any(r.get("tpu") for r in study["records"]):
        return None
    header = ["water", "instrument", "altitude [m]", "TVU median / p95 [cm]", "THU median / p95 [cm]",
              "points judged", "within TVU [%]", "within THU [%]"]

    def cm(q):
        return "–" if q["median"] is None else f"{100 * q['median']:.1f} / {100 * q['p95']:.1f}"

    rows = [[r["water"], r["instrument"], _altitude(r["altitude_m"]), cm(t["tvu_m"]), cm(t["thu_m"]),
             f"{t['points']:,}", _percent(t["vertical_within_tvu"]), _percent(t["horizontal_within_thu"])]
            for r in study["records"] if (t := r.get("tpu"))]
    return header, rows


def feature_table(study: dict) -> tuple[list[str], list[list[str]]] | None:
    """Per combination, the cubes of each size detected of those the scan reached, those no pulse reached or another
    object hid counted apart, when the study placed cubes."""
    sizes = list(dict.fromkeys(size for r in study["records"] for size in r.get("features", {})))
    if not sizes:
        return None
    header = ["water", "instrument", "altitude [m]"] + [f"{size} m cubes detected of those reached" for size in sizes]
    rows = [[r["water"], r["instrument"], _altitude(r["altitude_m"])]
            + [_detected(c) if (c := r["features"].get(size)) else "–" for size in sizes]
            for r in study["records"]]
    return header, rows


def _detected(cubes: dict) -> str:
    """"detected/reached", with the cubes no pulse reached or another object hid counted apart."""
    apart = [f"{cubes[k]} {k.replace('_', ' ')}" for k in ("not_reached", "shadowed") if cubes.get(k)]
    return f"{cubes['detected']}/{cubes.get('reached', cubes['placed'])}" + (f" ({', '.join(apart)})" if apart else "")


def near_zero_notes(study: dict) -> list[str]:
    """One sentence per combination that maps less than NEAR_ZERO of what it reaches: its largest gap cause and
    what that cause means."""
    notes = []
    for r in study["records"]:
        fraction = r["covered_fraction"]
        if fraction is None or fraction >= NEAR_ZERO or not r["reached_area_m2"]:
            continue
        cause, area = max(r["gaps_m2"].items(), key=lambda kv: kv[1])
        notes.append(f"{r['dir']}: {_percent(fraction)} % covered; {cause.replace('_', ' ')} takes "
                     f"{_percent(area / r['reached_area_m2'])} % of the reached area: {CAUSE_MEANINGS[cause]}.")
    return notes


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
        sections.append((MULTICHANNEL_TITLE, multi))
    objects = object_table(study)
    if objects[1]:
        sections.append(("Objects and cables", objects))
    if study.get("s44_orders"):
        sections.append(("IHO S-44 orders (Edition 6.0.0, 2020, Table 1)", orders_table(study)))
        sections.append(("S-44 compliance per water and altitude", compliance_table(study)))
    features = feature_table(study)
    if features:
        sections.append(("Feature detection", features))
    tpu = tpu_table(study)
    if tpu:
        sections.append(("Uncertainty per point (TPU) against the truth", tpu))
    return sections


def _s44_text(study: dict) -> str:
    s = study["study"]
    return ("Each order is judged on square cells of its own size: the cube it must detect where S-44's Table 1 gives "
            "one (Exclusive 0.5 m, Special 1 m, 1a 2 m), each cell needing at least "
            f"{s.get('order_min_soundings', 5)} soundings (Annex D's sample density); Orders 1b and 2, which ask no "
            "feature detection, on cells of their fixed THU (5 m, 20 m) with no count rule. A cell complies when at "
            "least 95 % of its soundings lie within the order's TVU = sqrt(a² + (b·d)²) at their depth d and its THU "
            "of their true position, and their predicted 95 % uncertainties (TVU, THU) are within the same limits. "
            "Compliant % is the share of the planned swath (the track flown, widened by altitude · tan(half the scan "
            "sector)) where the plan has one, else of the reached area, lying in reached cells that comply. Not "
            "checked: Exclusive's 200 % coverage (one pass covers a cell once) and the feature search of Exclusive, "
            "Special and 1a (measured apart by scanner-sim features); so Exclusive's figure is its uncertainty and "
            "density on 0.5 m cells, not a claim that the survey meets Exclusive Order. Source: "
            + study.get("s44_source", "") + ".")


def coverage_markdown(study: dict) -> str:
    """coverage.md: the tables a person reads."""
    parts = [f"# Coverage study: {study['scene']}\n", _definitions(study) + "\n"]
    for title, (header, rows) in _sections(study):
        parts.append(f"## {title}\n\n" + markdown_table(header, rows))
        if title == MULTICHANNEL_TITLE:
            parts += [f"- {n}" for n in multichannel_notes(study)] + [""]
    if study.get("s44_orders"):
        parts.append(_s44_text(study) + "\n")
    notes = near_zero_notes(study)
    if notes:
        parts.append("## Why some combinations map (next to) nothing\n\n" + "\n".join(f"- {n}" for n in notes) + "\n")
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
    """The speed-against-accuracy chart of the scene's fidelity levels, embedded with a sentence on how to read it,
    when ``scanner-sim tradeoff`` has written it beside the study; else nothing but one line in the page's notes
    (a section that only named a command read as a broken section)."""
    chart = out / TRADEOFF_DIR / "tradeoff.png"
    if not chart.exists():
        return ""
    return ("<h2>Speed against accuracy</h2><p>How far each fidelity level lies from the truth and from the "
            "reference level (vertical), against the pulses it simulates per second (horizontal): a level further "
            f"right is faster, a level lower is closer to the reference (written by <code>scanner-sim tradeoff "
            f"{html.escape(str(study['scene']))}</code>).</p>"
            f"<figure>{_image(chart, 'speed against accuracy')}<figcaption>speed against accuracy</figcaption></figure>")


#: Points the report's interactive view shows at most (one in every k in file order above it): about 9 MB of page.
REPORT_VIEW_MAX_POINTS = 200_000


def view_section(study: dict, out: Path) -> str:
    """The interactive 3-D view of the study's chosen pass (``view_pass``, default the first), the page of
    ``scanner-sim view --html`` inside an iframe's ``srcdoc``, so the report stays one file; nothing when the
    pass wrote no point cloud."""
    from scanner_sim.render import web_view

    name = study.get("view_pass") or (study["records"][0]["dir"] if study["records"] else None)
    if name is None:
        return ""
    try:
        files = web_view.PassFiles.of(out / name)
    except ValueError:
        return ""
    page = web_view.page_html(web_view.page_data(files, max_points=REPORT_VIEW_MAX_POINTS))
    return (f"<h2>Interactive view: {html.escape(name)}</h2><p>The pass's points in 3-D: drag to turn, wheel to "
            "zoom, switch the colouring in the panel (other passes: <code>scanner-sim view "
            f"{html.escape(name)} --html</code> in this folder, or <code>--view-pass</code>).</p>"
            f'<iframe title="3-D view of {html.escape(name)}" srcdoc="{html.escape(page, quote=True)}" '
            'style="width: 100%; height: 680px; border: 1px solid #ccc"></iframe>')


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
        if heading.startswith("S-44 compliance"):
            parts.append(f"<p>{html.escape(_s44_text(study))}</p>")
        if heading == MULTICHANNEL_TITLE and multichannel_notes(study):
            parts.append("<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in multichannel_notes(study)) + "</ul>")
    notes = near_zero_notes(study)
    if notes:
        parts.append("<h2>Why some combinations map (next to) nothing</h2><ul>"
                     + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    parts.append(tradeoff_section(study, out))
    if not (out / TRADEOFF_DIR / "tradeoff.png").exists():
        parts.append(f"<p>Speed against accuracy of the scene's fidelity levels: run <code>scanner-sim tradeoff "
                     f"{html.escape(str(study['scene']))}</code> and build the report again to see it here.</p>")
    parts.append(view_section(study, out))
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
