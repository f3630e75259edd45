"""Pictures: off-screen point-cloud renders and matplotlib plots produce real, non-trivial PNGs."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from scanner_sim.render import overlap_plot, point_cloud, point_colours, waveform_plot

OFFSET = np.array([500_000.0, 6_000_000.0, -40.0])
#: A picture with fewer distinct colours than this is a blank or a failed render.
MIN_DISTINCT_COLOURS = 20


def _distinct_colours(path) -> int:
    from matplotlib import image as mpimg

    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
    rgb = (img[..., :3] * 255).astype(np.uint8).reshape(-1, 3)
    return len(np.unique(rgb, axis=0))


def _scene(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform([-10, -5], [10, 5], (n, 2))
    z = 0.02 * rng.normal(size=n)
    cls = np.full(n, 40)
    cable = np.abs(xy[:, 1]) < 0.4
    cls[cable], z[cable] = 64, 0.3
    mine = np.hypot(xy[:, 0] - 4, xy[:, 1] - 2) < 0.8
    cls[mine], z[mine] = 65, 0.7
    xyz = np.column_stack([xy, z]) + OFFSET
    verts = np.array([[-11, -6, 0], [11, -6, 0], [11, 6, 0], [-11, 6, 0]], float) + OFFSET
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    return xyz, cls, verts, faces


def test_render_by_class_over_truth_mesh(tmp_path):
    xyz, cls, verts, faces = _scene()
    out = tmp_path / "render.png"
    point_cloud.render_point_cloud(out, xyz, cls, truth_vertices=verts, truth_faces=faces, title="cable_survey",
                                   window_size=(800, 500))
    assert out.stat().st_size > 10_000
    assert _distinct_colours(out) > MIN_DISTINCT_COLOURS
    assert os.listdir(tmp_path) == ["render.png"]


def test_render_by_scalar_with_scalar_bar(tmp_path):
    xyz, _, _, _ = _scene(seed=1)
    err = np.random.default_rng(1).normal(0, 0.02, len(xyz))
    out = tmp_path / "range_error.png"
    point_cloud.render_point_cloud(out, xyz, color_by="range_error", scalars=err, window_size=(800, 500))
    assert _distinct_colours(out) > MIN_DISTINCT_COLOURS


def test_render_rejects_bad_input(tmp_path):
    xyz, cls, _, _ = _scene(10)
    with pytest.raises(ValueError, match="scalars: required"):
        point_cloud.render_point_cloud(tmp_path / "a.png", xyz, color_by="snr")
    with pytest.raises(ValueError, match=r"classification: shape \(9,\)"):
        point_cloud.render_point_cloud(tmp_path / "a.png", xyz, cls[:9])
    with pytest.raises(ValueError, match=r"xyz: shape"):
        point_cloud.render_point_cloud(tmp_path / "a.png", xyz[:, :2], cls)
    assert os.listdir(tmp_path) == []


def test_class_table_reads_the_scene_labels():
    from scanner_sim.world.scene import LABELS

    table = point_colours.class_table()
    assert table[LABELS["cable"]] == "cable" and table[LABELS["seabed"]] == "seabed"
    assert point_colours.class_table({7: "noise"}) == {7: "noise"}


def test_class_colours_are_fixed():
    assert point_colours.CLASS_COLOURS["cable"] == (255, 140, 0)
    assert point_colours.CLASS_COLOURS["mine"] == (230, 25, 25)
    assert point_colours._class_colour(99, None) == point_colours._class_colour(99, "no such label")


def test_plot_waveforms_and_overlap(tmp_path):
    t = np.arange(600.0)
    rng = np.random.default_rng(0)
    clean = {f"CH{i}": 5 + 400 * np.exp(-(((t - 80 - 60 * i) / 4) ** 2)) for i in range(4)}
    noisy = {k: np.clip(np.rint(v + rng.normal(0, 2, t.size)), 0, 1023) for k, v in clean.items()}
    waveform_plot.plot_waveforms(tmp_path / "waveforms.png", t, noisy, clean, "pulse 17", adc_max_lsb=1023)
    assert _distinct_colours(tmp_path / "waveforms.png") > MIN_DISTINCT_COLOURS
    d = np.linspace(0.5, 6, 40)
    analytic = np.clip((d - 1.68) / 2.5, 0, 1)
    overlap_plot.plot_overlap(tmp_path / "overlap.png", d, analytic + rng.normal(0, 0.01, d.size), analytic,
                              dense_distance_m=np.linspace(0, 6, 400),
                              dense_analytic=np.clip((np.linspace(0, 6, 400) - 1.68) / 2.5, 0, 1))
    assert _distinct_colours(tmp_path / "overlap.png") > MIN_DISTINCT_COLOURS
    with pytest.raises(ValueError, match=r"noise_free\['CH1'\]: shape"):
        waveform_plot.plot_waveforms(tmp_path / "x.png", t, noisy, {"CH1": t[:5]}, None)
    with pytest.raises(ValueError, match="analytic: shape"):
        overlap_plot.plot_overlap(tmp_path / "x.png", d, d, d[:3])
    assert sorted(os.listdir(tmp_path)) == ["overlap.png", "waveforms.png"]


def test_importing_scanner_sim_does_not_import_plotting_libraries():
    """Every module of scanner_sim.render imports its plotting library inside its functions."""
    code = (
        "import importlib, pkgutil, sys, scanner_sim, scanner_sim.render, scanner_sim.io, scanner_sim.survey.georeference\n"
        "names = [m.name for m in pkgutil.iter_modules(scanner_sim.render.__path__, 'scanner_sim.render.')]\n"
        "assert 'scanner_sim.render.point_cloud' in names and len(names) >= 9, names\n"
        "for name in names: importlib.import_module(name)\n"
        "bad = [m for m in ('pyvista', 'vtk', 'matplotlib') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_prepared_render_is_the_same_picture(tmp_path):
    """The stage built before the points (plotter, truth mesh added at its own coordinates, shifted once the points
    give the centre) draws the PNG of the one-call render byte for byte, height colouring and title included."""
    xyz, cls, verts, faces = _scene(seed=2)
    normals = np.tile([0.0, 0.0, 1.0], (len(xyz), 1))
    options = {"title": "cable_survey: 7 points", "color_by": "height", "normals": normals}
    point_cloud.render_point_cloud(tmp_path / "one.png", xyz, cls, truth_vertices=verts, truth_faces=faces,
                                   window_size=(800, 500), **options)
    point_cloud.prepare_point_cloud(verts, faces, window_size=(800, 500))
    point_cloud.render_prepared_point_cloud(tmp_path / "prepared.png", xyz, cls, **options)
    assert (tmp_path / "one.png").read_bytes() == (tmp_path / "prepared.png").read_bytes()
    with pytest.raises(RuntimeError, match="no stage prepared"):
        point_cloud.render_prepared_point_cloud(tmp_path / "again.png", xyz, cls, **options)
