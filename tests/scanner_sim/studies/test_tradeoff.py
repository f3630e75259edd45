"""``scanner-sim tradeoff``: every level against the reference on the same pulses, its files, and the
reference's own convergence."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from scanner_sim.cli import main
from scanner_sim.config import load_scene
from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.render.report import tradeoff_section
from scanner_sim.studies.accuracy import vs_reference
from scanner_sim.studies.tradeoff import CONVERGENCE_SUBRAYS
from scanner_sim.survey.setup import PassOptions, PassSetup

FAILURES = Path(__file__).resolve().parents[3] / "scenes" / "failures"


@pytest.fixture(scope="module")
def step_edges(tmp_path_factory):
    """The step-edge failure scene through the command line: 400 pulses, one knob; returns (out dir, JSON)."""
    out = tmp_path_factory.mktemp("tradeoff")
    code = main(["tradeoff", str(FAILURES / "step_edges.yaml"), "--pulses", "400", "--waveform-pulses", "400",
                 "--knobs", "subrays=1", "--out", str(out), "--no-convergence"])
    assert code == 0
    return out, json.loads((out / "tradeoff.json").read_text())


def test_every_level_has_its_speed_and_both_sets_of_metrics(step_edges):
    out, result = step_edges
    assert set(result["levels"]) == set(FIDELITY_LEVELS) and set(result["knobs"]) == {"subrays=1"}
    for entry in [*result["levels"].values(), *result["knobs"].values()]:
        assert entry["pulses_per_s"] > 0
        assert {"median_abs_range_error_m", "p95_abs_range_error_m", "false_alarms_per_pulse",
                "hidden_points_per_pulse", "points_per_pulse"} <= set(entry["vs_truth"])
        assert {"missing_per_pulse", "extra_per_pulse", "median_position_diff_m", "p95_position_diff_m",
                "class_agreement", "coverage_diff", "waveform_r2"} <= set(entry["vs_reference"])
    for name in ("tradeoff.png", "tradeoff.md", "tradeoff.json"):
        assert (out / name).is_file()
    assert "| subrays=1 |" in (out / "tradeoff.md").read_text()


def test_fewer_pulses_than_the_pass_are_taken_from_its_middle_and_the_table_says_so(step_edges):
    """400 of the scene's 2,000 pulses (its survey.max_pulses, one chunk's worth): one stretch about the middle of the
    pass, its slots in tradeoff.json and the table's first line."""
    out, result = step_edges
    assert result["pulses"] == 400
    ((first, end),) = result["stretches"]
    assert 600 <= first and end <= 1400
    assert f"about the middle of the pass (pulse slots {first:,}-{end - 1:,})" in (out / "tradeoff.md").read_text()


def test_where_auto_falls_back_the_table_says_why(step_edges):
    """The step edges are panels, not a height-field seabed: auto can prove no pulse, casts them as balanced does,
    and its decisions (in the JSON, and under the table) say so and why; it still collapses the footprints on one
    flat step."""
    out, result = step_edges
    decisions = result["levels"]["auto"]["decisions"]
    assert decisions["proven"] == 0 and "height-field" in decisions["falls_back"]
    assert 0 < decisions["simple"] < 1 and 1 <= decisions["channels_per_window"] <= decisions["channels"]
    assert all("decisions" not in result["levels"][n] for n in ("fast", "balanced", "reference"))
    table = (out / "tradeoff.md").read_text()
    assert "`auto` decided" in table and decisions["falls_back"] in table


def test_the_range_bias_is_signed_and_no_larger_than_the_median_error(step_edges):
    """The median signed range error (the bias auto must keep within balanced's) is bounded by the median absolute
    error: at least half the errors lie beyond the median in magnitude. The table prints it."""
    out, result = step_edges
    for entry in result["levels"].values():
        truth = entry["vs_truth"]
        assert abs(truth["median_range_bias_m"]) <= truth["median_abs_range_error_m"] + 1e-6
    assert "range bias [m]" in (out / "tradeoff.md").read_text()


def test_more_timed_passes_change_only_the_speeds():
    """A seed fixes the points, so timing each run once or three times (round-robin, the fastest kept) gives the
    same metrics; only pulses_per_s may move, and the JSON says how many passes timed it and their median."""
    from scanner_sim.studies.tradeoff import tradeoff

    config = load_scene(FAILURES / "step_edges.yaml")
    once, thrice = (tradeoff(config, ("fast", "auto"), (), pulses=300, waveform_pulses=100, convergence=False,
                             repeat=r) for r in (1, 3))
    assert (once["timed_passes"], thrice["timed_passes"]) == (1, 3)
    for name in ("fast", "auto"):
        a, b = once["levels"][name], thrice["levels"][name]
        assert a["vs_truth"] == b["vs_truth"] and a["vs_reference"] == b["vs_reference"]
        assert b["pulses_per_s"] > 0
        # the fastest of three passes is at least their median; one pass is its own median
        assert 0 < b["median_pulses_per_s"] <= b["pulses_per_s"]
        assert a["median_pulses_per_s"] == a["pulses_per_s"]


def test_the_reference_against_itself_is_exact(step_edges):
    """The reference run twice on the same pulses and seed is the same run: nothing missing or extra, no
    position difference, every class agrees, waveforms identical."""
    ref = step_edges[1]["levels"]["reference"]["vs_reference"]
    assert (ref["missing_per_pulse"], ref["extra_per_pulse"], ref["p95_position_diff_m"]) == (0.0, 0.0, 0.0)
    assert ref["class_agreement"] == 1.0 and ref["waveform_r2"] == 1.0 and ref["coverage_diff"] == 0.0


def test_one_subray_per_pulse_misses_step_edges_the_reference_sees(step_edges):
    """Across steps of 0.2-2 m, a beam of one ray ranges one surface where the reference's 91 sub-rays straddle
    the edge and range two: one ray per pulse has returns missing against the reference, and a worse waveform."""
    result = step_edges[1]
    one, balanced = result["knobs"]["subrays=1"]["vs_reference"], result["levels"]["balanced"]["vs_reference"]
    assert one["missing_per_pulse"] > balanced["missing_per_pulse"]
    assert one["waveform_r2"] < balanced["waveform_r2"] < 1.0


def test_a_bad_level_is_refused_in_one_line(capsys):
    assert main(["tradeoff", "cable_survey", "--levels", "fastest"]) == 2
    err = capsys.readouterr().err
    assert "fastest" in err and len(err.strip().splitlines()) == 1


def test_the_study_report_embeds_the_chart_written_beside_it(step_edges, tmp_path):
    out, result = step_edges
    (tmp_path / "tradeoff").mkdir()
    (tmp_path / "coverage").mkdir()
    (tmp_path / "tradeoff" / "tradeoff.png").write_bytes((out / "tradeoff.png").read_bytes())
    section = tradeoff_section({"scene": "step_edges"}, tmp_path / "coverage")
    assert "scanner-sim tradeoff step_edges" in section and "data:image/png;base64," in section
    assert "data:image" not in tradeoff_section({"scene": "step_edges"}, tmp_path / "elsewhere" / "coverage")


def test_the_reference_has_converged_on_the_cable_survey():
    """Running the reference at 217 sub-rays (8 rings against 5) moves 95 % of cable_survey's points by less than
    1 cm and no return appears or vanishes (docs/fidelity.md states it)."""
    base = PassSetup.build(load_scene("cable_survey"), PassOptions(max_pulses=600))
    slots = np.concatenate(list(base.slot_chunks()))
    reference = FIDELITY_LEVELS["reference"]
    coarse = base.at_level(reference).simulate_chunk(slots).points
    fine = base.at_level(replace(reference, subrays=CONVERGENCE_SUBRAYS)).simulate_chunk(slots).points
    m = vs_reference(fine, coarse, slots.size)
    assert m["missing_per_pulse"] == 0.0 and m["extra_per_pulse"] == 0.0
    assert m["p95_position_diff_m"] < 0.01


def test_points_on_a_plate_hidden_from_the_receiver_count_as_hidden():
    """The hidden-plate failure scene without shadow rays (the fast level before shadow rays): a point per pulse, every one on
    the plate the visor hides from the receiver; the eight-surface staircase's returns behind edges are not."""
    from scanner_sim.studies.tradeoff import hidden_from_receiver

    blind = replace(FIDELITY_LEVELS["fast"], shadow_rays=False)
    for scene, hidden in (("hidden_plate", 1.0), ("eight_surfaces", 0.0)):
        setup = PassSetup.build(load_scene(str(FAILURES / f"{scene}.yaml")), PassOptions(max_pulses=100), level=blind)
        points = setup.simulate_chunk(np.concatenate(list(setup.slot_chunks()))).points
        assert len(points) >= 100
        assert np.mean(hidden_from_receiver(setup, points)) == hidden
