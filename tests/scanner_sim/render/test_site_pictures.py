"""Pictures of a real site: render.png shows a seabed's relief in colour (height, hill-shaded, colour bar, scale bar)
and the plan maps tick in map coordinates a person reads (scanner_sim/render/point_cloud.py, point_colours.py,
plan_map.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.figure import Figure

from scanner_sim.render.plan_map import finish_plan_map
from scanner_sim.render.point_cloud import scale_bar_m
from scanner_sim.survey import pictures
from scanner_sim.world.terrain import HeightField

E0, N0 = 614_160.0, 4_494_750.0  # NAD83 / UTM 18N, where real_site lies


def test_seabed_render_shows_its_relief_in_colour(tmp_path):
    """A seabed 8 m deeper in the west than in the east (real_site's relief over its 70 m), rendered as a pass
    renders it: the western third of its points must be drawn in another colour than the eastern third.

    Root cause of the failure this pins: render.png coloured every point by class, so a seabed was one beige
    whatever its relief; real_site's 8 m of relief was a flat slab."""
    from PIL import Image

    x = np.arange(0.0, 70.0, 1.0)
    heights = np.tile(-17.0 + 8.0 * x / 70.0, (50, 1))  # rising eastwards
    field = HeightField(E0, N0, 1.0, heights)
    rng = np.random.default_rng(0)
    xy = np.c_[E0 + rng.uniform(0, 69, 20_000), N0 + rng.uniform(0, 49, 20_000)]
    xyz = np.c_[xy, field.height(xy[:, 0], xy[:, 1])]
    vertices, faces = field.mesh()
    scene = SimpleNamespace(heightfield=field, vertices=vertices, faces=faces)
    sample = SimpleNamespace(xyz=xyz, classification=np.full(len(xyz), 40, np.uint8))
    path = tmp_path / "render.png"
    pictures.render_points(path, sample, scene, SimpleNamespace(label="site", fidelity="fast"), window_size=(800, 500))
    image = np.asarray(Image.open(path).convert("RGB")).astype(float)
    background = image[-1, -1]
    drawn = np.abs(image - background).sum(axis=2) > 60
    cols = np.nonzero(drawn[100:420].any(axis=0))[0]  # the points' rows, under the title, above the scale bar
    third = (cols.max() - cols.min()) // 3
    west = image[100:420, cols.min():cols.min() + third][drawn[100:420, cols.min():cols.min() + third]].mean(axis=0)
    east = image[100:420, cols.max() - third:cols.max()][drawn[100:420, cols.max() - third:cols.max()]].mean(axis=0)
    assert np.abs(east - west).sum() > 80, (west, east)


def test_seabed_normals_are_the_height_fields_slope():
    """On a plane rising 1 in 2 eastwards the upward normal is (-1, 0, 2) / sqrt(5), by hand."""
    field = HeightField(0.0, 0.0, 0.5, np.tile(0.5 * np.arange(0.0, 10.0, 0.5), (20, 1)))
    normal = pictures.seabed_normals(field, np.array([3.0, 4.2]), np.array([5.0, 2.7]))
    assert normal == pytest.approx(np.tile(np.array([-1.0, 0.0, 2.0]) / np.sqrt(5.0), (2, 1)))


def test_scale_bar_takes_a_round_length_that_fits():
    """1, 2 or 5 times a power of ten, the longest within the width: 72 m (real_site) -> 50 m in 10 m steps,
    7 m -> 5 m, 0.3 m -> 0.2 m in 5 cm steps."""
    assert scale_bar_m(72.0) == (50.0, 5)
    assert scale_bar_m(7.0) == (5.0, 5)
    assert scale_bar_m(0.3) == pytest.approx((0.2, 4))
    assert scale_bar_m(10.0) == (10.0, 5)


def test_plan_map_ticks_read_as_map_coordinates(tmp_path):
    """A map over UTM northings near 4,494,780 m must tick 4494760 ... not 760 under a "+4.494e6" offset.

    Root cause: matplotlib's default ScalarFormatter moves large, close values into an offset text."""
    fig = Figure()
    ax = fig.add_subplot()
    ax.imshow(np.zeros((10, 10)), extent=(E0, E0 + 70, N0, N0 + 60), origin="lower")
    finish_plan_map(fig, ax, tmp_path / "map.png", "t")
    fig.canvas.draw()
    assert ax.yaxis.get_offset_text().get_text() == ""
    assert ax.xaxis.get_offset_text().get_text() == ""
    labels = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
    assert any(label.startswith("44947") or label.startswith("44948") for label in labels), labels
