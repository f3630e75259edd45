"""What a reader of the coverage report tripped on (issue: report.html and its pictures), each fixed and checked."""

import numpy as np

from scanner_sim.render import viz


def test_render_legend_ends_inside_the_window(tmp_path):
    """At the study's 960 x 600 renders the class legend ran off the right edge ("seabed, class 40" cut after
    "4"). Root cause: the legend's left edge sat at 79 % of the width whatever its labels' length."""
    from PIL import Image

    rng = np.random.default_rng(0)
    pts = rng.uniform(-5, 5, (3000, 3)) * [1, 1, 0.1]
    classes = rng.choice([7, 40, 43, 64, 65, 66, 67, 68, 69, 70], 3000).astype(np.uint8)
    path = tmp_path / "render.png"
    viz.render_point_cloud(path, pts, classes, title="t", window_size=(960, 600))
    image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    background = image[-1, -1]
    legend_rows = image[:300]  # the legend's ten lines, above the points
    right_edge = legend_rows[:, -6:]
    assert np.abs(right_edge - background).max() <= 8, "legend text reaches the window's right edge"
    # and the legend is there: coloured text in the right quarter of its rows
    assert (np.abs(legend_rows[:, 720:] - background).sum(axis=2) > 100).sum() > 500
