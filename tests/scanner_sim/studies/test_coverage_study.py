"""The coverage study end to end: combinations, gate rule, outputs, the self-contained report, the CLI."""

import base64
import contextlib
import io as stdio
import json
import re
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest
from conftest import chromium, page_pixels
from matplotlib import image as mpimg

from muls.infra.errors import ParameterError
from scanner_sim.cli import main
from scanner_sim.config import load_scene
from scanner_sim.studies.coverage_study import StudyPlan, combination_config, combination_name


@pytest.fixture(scope="module")
def cable_survey():
    return load_scene("cable_survey")


def test_gate_follows_the_nadir_echo(cable_survey):
    base = cable_survey.instrument.gate_delay_ns
    speed = 0.2197892  # m/ns, coastal ocean group velocity (muls.water.properties)
    same = combination_config(cable_survey, "coastal_ocean", 6.0, "mul2023")
    assert same.instrument.gate_delay_ns == pytest.approx(base)
    higher = combination_config(cable_survey, "coastal_ocean", 10.0, "mul2023")
    assert higher.platform.altitude_m == 10.0
    assert higher.instrument.gate_delay_ns == pytest.approx(base + 2 * 4.0 / speed, rel=1e-5)
    assert combination_config(cable_survey, "coastal_ocean", 1.0, "mul2023").instrument.gate_delay_ns == 0.0
    fixed = combination_config(cable_survey, "coastal_ocean", 10.0, "mul2023", gate="fixed")
    assert fixed.instrument.gate_delay_ns == base
    single = combination_config(cable_survey, "turbid_harbor", 10.0, "single_channel")
    assert single.instrument.preset == "single_channel" and single.instrument.gate_delay_ns is None


@pytest.mark.parametrize("kw, key", [
    ({"waters": ("clean_ocean", "milk")}, "water"), ({"altitudes_m": (3.0, -1.0)}, "altitudes_m"),
    ({"instruments": ("mul2023", "lidar9")}, "instruments"), ({"gate": "auto"}, "gate"),
    ({"waters": ()}, "waters"), ({"altitudes_m": (3.0, 3.0)}, "altitudes_m")])
def test_bad_plans_name_the_key(kw, key):
    with pytest.raises(ParameterError, match=key):
        StudyPlan(**kw)


def test_altitude_of_a_static_scene_cannot_change():
    with pytest.raises(ParameterError, match="altitude"):
        combination_config(load_scene("pool_panel"), "pool", 3.0, "mul2023")


@pytest.mark.parametrize("argv, words", [
    (["coverage", "--waters", "milk"], ["water", "milk", "clean_ocean"]),
    (["coverage", "pool_panel"], ["pool_panel", "seabed"]),
    (["coverage", "pool_panel", "--altitudes-m", "3"], ["pool_panel", "seabed"]),
    (["coverage", "--cell-m", "-1"], ["cell_m", "-1"]),
    (["coverage", "--altitudes-m", "0"], ["altitudes_m", "0"])])
def test_coverage_command_errors_are_one_line(argv, words, tmp_path, capsys):
    assert main(argv + ["--out", str(tmp_path / "x"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and all(w in err for w in words), err
    assert not (tmp_path / "x" / "coverage.json").exists()


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.links, self.tables, self.stack = [], [], 0, []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.images.append(a["src"])
        if tag in ("link", "script") or (tag == "a" and "href" in a):
            self.links.append(a)
        self.tables += tag == "table"


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    """Two waters at 6 m, 3000 pulses each, through the command line; returns (out dir, its stdout)."""
    out = tmp_path_factory.mktemp("study") / "study"
    printed = stdio.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["coverage", "cable_survey", "--waters", "clean_ocean", "turbid_harbor", "--instruments",
                     "mul2023", "--altitudes-m", "6", "--max-pulses", "3000", "--out", str(out), "--quiet"])
    assert code == 0
    return out, printed.getvalue()


def test_study_outputs_and_self_contained_report(small_study):
    out, printed = small_study
    assert printed.strip() == str(out / "coverage.json")
    study = json.loads((out / "coverage.json").read_text())
    assert [(r["water"], r["instrument"], r["altitude_m"]) for r in study["records"]] == [
        ("clean_ocean", "mul2023", 6.0), ("turbid_harbor", "mul2023", 6.0)]
    for r in study["records"]:
        assert r["pulses"] == 3000
        assert 0.0 < r["covered_fraction"] <= 1.0
        assert r["settings"]["tolerance_m"] == 0.15 and r["settings"]["gate_delay_ns"] == 35.0
        assert sum(r["gaps_m2"].values()) == pytest.approx(r["reached_area_m2"] - r["covered_area_m2"])
        for file in ("points.las", "summary.json", "coverage_grid.npz", "coverage_map.png", "s44_map.png", "calibration.png",
                     "render.png"):
            assert (out / r["dir"] / file).is_file()
        assert not (out / r["dir"] / "scene.ply").exists()  # one truth mesh for the whole study
    assert (out / "scene.ply").is_file()
    markdown = (out / "coverage.md").read_text()
    coverage_table = markdown.split("\n## Coverage\n")[1].split("\n## ")[0]
    assert coverage_table.count("\n| clean_ocean | mul2023 | 6 |") == 1
    assert coverage_table.count("\n| turbid_harbor | mul2023 | 6 |") == 1
    assert "| export_cable (cable, 30.5 m) |" in markdown

    page = _Page()
    page.feed((out / "report.html").read_text())
    page.close()
    assert page.links == []  # nothing outside the file
    assert page.tables >= 2
    assert len(page.images) == 1 + 4 * len(study["records"])  # chart, then two maps, a TPU chart and a render each
    for src in page.images:
        head, data = src.split(",", 1)
        assert head == "data:image/png;base64"
        picture = mpimg.imread(stdio.BytesIO(base64.b64decode(data, validate=True)), format="png")
        assert picture.shape[0] > 100 and picture.shape[1] > 100
        assert np.ptp(picture[..., :3]) > 0.1  # not a blank picture


def _hex_rgb(colour):
    return tuple(int(colour[i:i + 2], 16) for i in (1, 3, 5))


def test_report_opens_in_headless_chromium_with_every_picture(small_study, tmp_path):
    """Chromium renders the page; the screenshot shows the map's covered teal and the renders' navy.
    .ci/run installs Chromium and sets MULS_REQUIRE_CHROMIUM=1, so CI never skips this."""
    from scanner_sim.render.plan_map import COVERAGE_COLOURS

    out, _ = small_study
    rgb = page_pixels(out / "report.html", tmp_path / "report.png", height=6000)
    colours = {tuple(c) for c in np.unique(rgb, axis=0)}
    assert _hex_rgb(COVERAGE_COLOURS["covered"]) in colours  # a coverage map is drawn
    assert _hex_rgb("#0b1a2a") in colours  # a point-cloud render is drawn (its background)
    assert len(colours) > 500  # pictures, not just text on white


def test_coverage_json_carries_s44_orders_and_compliance_per_record(small_study):
    from scanner_sim.metrics import s44

    out, _ = small_study
    study = json.loads((out / "coverage.json").read_text())
    assert study["s44_orders"] == s44.orders_table()
    assert set(study["s44_orders"]["exclusive"]) >= {"tvu_a_m", "tvu_b", "thu_m", "thu_depth_fraction", "feature_m"}
    for r in study["records"]:
        assert list(r["orders"]) == ["exclusive", "special", "1a", "1b", "2"]
        fractions = [r["orders"][name]["compliant_fraction"] for name in r["orders"]]
        assert all(0.0 <= f <= 1.0 for f in fractions)
        # a cell meeting a stricter order meets every looser one with the same limits or wider
        assert fractions[0] <= fractions[1] <= fractions[2] <= fractions[4]
        assert r["settings"]["order_min_soundings"] == s44.DEFAULT_MIN_SOUNDINGS
        assert 0.0 <= r["planned_swath"]["reached_fraction"] <= 1.0
    text = (out / "coverage.md").read_text()
    assert "## IHO S-44 orders" in text and "## S-44 compliance per water and altitude" in text


def test_report_s44_section_opens_in_chromium_with_every_image_decoding(small_study, tmp_path):
    """A copy of report.html with a script that counts, once loaded, the images Chromium decoded and the sections."""
    browser = chromium()
    out, _ = small_study
    probe = ('<script>window.addEventListener("load", () => { const imgs = [...document.images];'
             ' const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;'
             ' const d = document.createElement("div"); d.id = "probe";'
             ' d.textContent = `${imgs.length} ${ok} ` + [...document.querySelectorAll("h2")].map(h => h.textContent)'
             '.join(";"); document.body.appendChild(d); });</script>')
    page = tmp_path / "report.html"
    page.write_text((out / "report.html").read_text().replace("</body>", probe + "</body>"))
    run = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000",
                          "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-2000:]
    found = re.search(r'<div id="probe">(\d+) (\d+) ([^<]*)</div>', run.stdout)
    assert found, run.stdout[-2000:]
    images, decoded, sections = int(found[1]), int(found[2]), found[3].split(";")
    assert images == decoded == 1 + 4 * 2  # the chart; per pass its coverage map, S-44 map, TPU chart and render
    assert "S-44 compliance per water and altitude" in sections and "IHO S-44 orders (Edition 6.0.0, 2020, Table 1)" \
        in sections and "Uncertainty per point (TPU) against the truth" in sections


def test_coverage_map_colours_cells_by_cause(tmp_path):
    from scanner_sim.metrics.coverage import GAP_CAUSES
    from scanner_sim.render.coverage_map import plot_coverage_map
    from scanner_sim.render.plan_map import COVERAGE_COLOURS

    state = np.full((40, 80), -2)
    state[10:30, 10:70] = -1
    state[15:20, 30:40] = GAP_CAUSES.index("below_threshold")
    plot_coverage_map(tmp_path / "m.png", state, (0, 20, 0, 10), GAP_CAUSES, title="t")
    rgb = (mpimg.imread(tmp_path / "m.png")[..., :3] * 255).round().astype(int)
    colours = {_hex_rgb(COVERAGE_COLOURS[n]): n for n in ("covered", "below_threshold", "masked_by_backscatter")}
    found = {colours[c] for c in map(tuple, rgb.reshape(-1, 3)) if c in colours}
    assert found == {"covered", "below_threshold"}


def test_combination_names_are_unique_and_readable():
    plan = StudyPlan(altitudes_m=(3, 5.5), instruments=("mul2023", "single_channel"))
    names = [combination_name(*c) for c in plan.combinations(load_scene("cable_survey"))]
    assert len(set(names)) == len(names) == 12
    assert "turbid_harbor-single_channel-5.5m" in names
    assert all(re.fullmatch(r"[a-z_]+-[a-z0-9_]+-[0-9.]+m", n) for n in names)


#: Largest covered-fraction inversion accepted as a tie (0.1 % of the reached area). Where two combinations
#: both map all but a few cells, those cells (single pulses on steep, saturating facets, out_of_tolerance)
#: decide: the same combination varies with the seed by one cell, 0.007 % (docs/coverage.md, lawnmower at 3 m).
TIE = 0.001
SURVEY_SCENES = ("cable_survey", "mine_field", "seabed_lawnmower")
ALTITUDES_M = (3.0, 5.0, 8.0, 12.0)


@pytest.mark.slow
@pytest.mark.parametrize("scene", SURVEY_SCENES)
def test_coverage_falls_with_turbidity_and_altitude_and_multichannel_wins(scene, tmp_path):
    from muls.ranging.returns import DROPOUT_CAUSES

    study = run_study_quietly(scene, tmp_path)
    cov = {(r["water"], r["instrument"], r["altitude_m"]): r for r in study["records"]}
    waters = ("clean_ocean", "coastal_ocean", "turbid_harbor")
    frac = lambda w, i, a: cov[(w, i, a)]["covered_fraction"]  # noqa: E731
    density = lambda w, i: sum(cov[(w, i, a)]["valid_points_in_reach"] for a in ALTITUDES_M)  # noqa: E731
    # The water ordering is the scenes' own instrument's. A single channel, its gain set for the water, clips
    # on every near echo in clear water at 3 m and loses cells to clipped ranging on steep facets: it maps
    # less in clean than in coastal water there (about 0.1 %), the dynamic-range limit MULS is built against.
    for inst in ("mul2023",):
        for clearer, murkier in zip(waters, waters[1:]):
            for a in ALTITUDES_M:
                # A combination's count varies with the seed by one cell (docs/coverage.md): two cells are a tie.
                r = cov[(clearer, inst, a)]
                tie = max(TIE, 2 * r["settings"]["cell_m"] ** 2 / r["reached_area_m2"])
                assert frac(clearer, inst, a) >= frac(murkier, inst, a) - tie, (clearer, murkier, inst, a)
            assert density(clearer, inst) > density(murkier, inst), (clearer, murkier, inst)
        mean = [np.mean([frac(w, inst, a) for a in ALTITUDES_M]) for w in waters]
        assert mean[0] >= mean[1] - TIE and mean[1] > mean[2] + 0.05
    for inst in ("mul2023", "single_channel"):
        turbid = [frac("turbid_harbor", inst, a) for a in ALTITUDES_M]
        assert all(lo <= hi + TIE for hi, lo in zip(turbid, turbid[1:])), turbid
        assert turbid[-1] < turbid[0] - 0.3, turbid
    # Detected: a cell with a point, within the tolerance or not. Multiply scattered light ranges a turbid echo
    # long (first returns +0.39 m under the track at 6 m slant range, docs/coverage.md), past the tolerance,
    # whichever instrument detects it.
    detected = lambda w, i, a: frac(w, i, a) + cov[(w, i, a)]["gaps_m2"]["out_of_tolerance"] / \
        cov[(w, i, a)]["reached_area_m2"]  # noqa: E731
    for (w, i, a), r in cov.items():
        if i == "mul2023":
            # Wherever the three channels detect less than the one, the column blinds the mul2023's fixed
            # gains (set for the pond) where the single channel's gain is set for the water.
            masked = r["gaps_m2"]["masked_by_backscatter"] / r["reached_area_m2"]
            assert detected(w, i, a) + masked >= detected(w, "single_channel", a) - TIE, (w, a)
        # every gap has a cause, and a plan cell is never missed for another surface
        assert sum(r["gaps_m2"].values()) == pytest.approx(r["reached_area_m2"] - r["covered_area_m2"])
        assert r["gaps_m2"]["other_surface"] == 0.0
        assert set(r["gaps_m2"]) == set(DROPOUT_CAUSES) | {"out_of_tolerance", "other_surface"}
    # the gated far channel detects what one channel cannot in turbid water at 5 and 8 m
    turbid_gain = sum(detected("turbid_harbor", "mul2023", a) - detected("turbid_harbor", "single_channel", a)
                      for a in (5.0, 8.0))
    assert turbid_gain > 0.2
    # and where one channel runs out of dynamic range (coastal water, 12 m) it maps at least as much
    assert frac("coastal_ocean", "mul2023", 12.0) >= frac("coastal_ocean", "single_channel", 12.0) - TIE


def run_study_quietly(scene, out):
    from scanner_sim.studies.coverage_study import run_study

    plan = StudyPlan(altitudes_m=ALTITUDES_M, instruments=("mul2023", "single_channel"))
    return run_study(load_scene(scene), plan, out, max_pulses=20000, render=False, progress=False)
