"""What a reader of the coverage report tripped on (issue: report.html and its pictures), each fixed and checked."""

import numpy as np

from scanner_sim.metrics.coverage import GAP_CAUSES
from scanner_sim.render import point_cloud, sweep_charts


def test_render_legend_ends_inside_the_window(tmp_path):
    """At the study's 960 x 600 renders the class legend ran off the right edge ("seabed, class 40" cut after
    "4"). Root cause: the legend's left edge sat at 79 % of the width whatever its labels' length."""
    from PIL import Image

    rng = np.random.default_rng(0)
    pts = rng.uniform(-5, 5, (3000, 3)) * [1, 1, 0.1]
    classes = rng.choice([7, 40, 43, 64, 65, 66, 67, 68, 69, 70], 3000).astype(np.uint8)
    path = tmp_path / "render.png"
    point_cloud.render_point_cloud(path, pts, classes, title="t", window_size=(960, 600))
    image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    background = image[-1, -1]
    legend_rows = image[:300]  # the legend's ten lines, above the points
    right_edge = legend_rows[:, -6:]
    assert np.abs(right_edge - background).max() <= 8, "legend text reaches the window's right edge"
    # and the legend is there: coloured text in the right quarter of its rows
    assert (np.abs(legend_rows[:, 720:] - background).sum(axis=2) > 100).sum() > 500


def test_coverage_chart_keeps_mul2023_visible_under_single_channel():
    """At 100 % both instruments of a water sat at the same x with the same marker size, and single_channel's
    squares, drawn last, hid mul2023's circles. Root cause: curves were set apart per water only."""
    keys = [(w, i) for w in ("clean_ocean", "coastal_ocean") for i in ("mul2023", "single_channel")]
    layout = sweep_charts.curve_layout(keys, span=3.0)
    offsets = [layout[k][0] for k in keys]
    assert len(set(offsets)) == len(keys)  # no two curves at the same x
    for earlier, later in zip(keys, keys[1:]):  # each drawn on top of the one before, smaller
        assert layout[later][3] > layout[earlier][3] and layout[later][2] < layout[earlier][2]


def test_near_zero_combination_is_explained_in_words():
    """A turbid combination read 0.0 % covered and nothing on the page said why. Root cause: the report listed gap
    areas by cause name only; a planner needs the cause's meaning."""
    from scanner_sim.render import report

    def record(name, fraction, gaps):
        return {"dir": name, "covered_fraction": fraction, "reached_area_m2": 100.0, "gaps_m2": gaps}

    study = {"records": [record("turbid-12m", 0.0, {"below_threshold": 99.0, "out_of_tolerance": 1.0}),
                         record("clean-12m", 0.99, {"out_of_tolerance": 1.0})]}
    (note,) = report.near_zero_notes(study)
    assert note.startswith("turbid-12m: 0.0 % covered; below threshold takes 99.0 % of the reached area")
    assert report.CAUSE_MEANINGS["below_threshold"] in note
    assert set(report.CAUSE_MEANINGS) == set(GAP_CAUSES)  # every cause has its sentence
