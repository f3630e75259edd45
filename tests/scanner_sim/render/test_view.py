"""``scanner-sim view``: a LAS (and the scene.ply beside it) rendered off-screen to a PNG per colouring."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from scanner_sim import cli, io
from scanner_sim.records.point_records import PointRecords
from scanner_sim.render import point_cloud, point_colours
from scanner_sim.world.scene import LABELS

OFFSET = np.array([500_000.0, 6_000_000.0, -40.0])
SIZE = (400, 260)  # --window-size: small, so the renders stay fast
COLOURS = ("class", "intensity", "channel", "range_error", "snr")
#: A picture with fewer distinct colours than this is a blank or a failed render.
MIN_DISTINCT_COLOURS = 20


def _records(n: int = 4000, seed: int = 0) -> PointRecords:
    """A sand seabed (z ~ 0) crossed by a cable strip (z = 0.3) along x; every field varies in space."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([-10, -5], [10, 5], (n, 2))
    z = 0.02 * rng.normal(size=n)
    cable = np.abs(xy[:, 1]) < 0.6
    z[cable] = 0.3
    cls = np.where(cable, LABELS["cable"], LABELS["seabed"])
    pulse = np.arange(n)
    return PointRecords(
        gps_time_s=pulse * 2e-4,
        xyz=np.column_stack([xy, z]) + OFFSET,
        intensity=np.clip((xy[:, 0] + 10) * 3000, 0, 65535).astype(np.int64),
        return_number=np.ones(n, int),
        number_of_returns=np.ones(n, int),
        classification=cls,
        scan_angle_deg=rng.uniform(-60.0, 60.0, n),
        channel=1 + (xy[:, 1] > 0).astype(int) + (xy[:, 0] > 0).astype(int),
        amplitude_lsb=rng.uniform(0, 1023, n),
        snr=np.abs(xy[:, 1]) * 40.0,
        saturated=np.zeros(n, bool),
        true_range_m=rng.uniform(1, 12, n),
        range_error_m=0.01 * xy[:, 0] + rng.normal(0, 0.002, n),
        incidence_deg=rng.uniform(0, 89, n),
        object_id=np.where(cable, 1, 0),
        leg=np.ones(n, int),
        pulse_index=pulse,
    )


@pytest.fixture(scope="module")
def survey_dir(tmp_path_factory):
    """points.las and scene.ply side by side, as ``scanner-sim run`` writes them."""
    out = tmp_path_factory.mktemp("pass")
    io.write_las(out / "points.las", _records(), offset_m=OFFSET)
    verts = np.array([[-11, -6, -0.05], [11, -6, -0.05], [11, 6, -0.05], [-11, 6, -0.05]], float) + OFFSET
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    io.write_scene_ply(out / "scene.ply", verts, faces, [LABELS["seabed"]] * 2, [0, 0])
    return out


def _view(*argv) -> int:
    return cli.main(["view", *map(str, argv), "--window-size", *map(str, SIZE)])


def _image(path) -> np.ndarray:
    from matplotlib import image as mpimg

    img = mpimg.imread(path)
    return (img[..., :3] * 255).round().astype(np.int16)


def _pixels_near(img: np.ndarray, rgb, tol: int = 12) -> int:
    return int(np.all(np.abs(img - np.asarray(rgb)) <= tol, axis=-1).sum())


def test_every_colouring_renders_a_distinct_picture(survey_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    images = {}
    for colour in COLOURS:
        png = tmp_path / f"{colour}.png"
        assert _view(survey_dir / "points.las", "--color", colour, "--screenshot", png) == 0
        assert capsys.readouterr().out.strip() == str(png)
        img = _image(png)
        assert img.shape == (SIZE[1], SIZE[0], 3), colour
        assert len(np.unique(img.reshape(-1, 3), axis=0)) > MIN_DISTINCT_COLOURS, colour
        images[colour] = img
    sand, orange = point_colours.CLASS_COLOURS["seabed"], point_colours.CLASS_COLOURS["cable"]
    assert _pixels_near(images["class"], sand) > 2000 and _pixels_near(images["class"], orange) > 500
    assert _pixels_near(images["intensity"], orange) < _pixels_near(images["class"], orange) / 10
    for a, b in itertools.combinations(COLOURS, 2):
        assert np.abs(images[a] - images[b]).mean() > 5.0, (a, b)


def test_without_display_writes_beside_the_las_and_no_mesh_drops_the_truth(survey_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    las = tmp_path / "points.las"
    las.write_bytes((survey_dir / "points.las").read_bytes())  # no scene.ply beside this copy
    assert _view(las, "--color", "snr", "--point-size", "2") == 0
    png = tmp_path / "points.snr.png"
    assert capsys.readouterr().out.strip() == str(png)
    assert _image(png).shape == (SIZE[1], SIZE[0], 3)

    with_mesh, without = tmp_path / "mesh.png", tmp_path / "nomesh.png"
    assert _view(survey_dir / "points.las", "--screenshot", with_mesh, "--max-points", "1000") == 0
    assert _view(survey_dir / "points.las", "--screenshot", without, "--max-points", "1000", "--no-mesh") == 0
    navy = tuple(int(point_cloud._BACKGROUND[i:i + 2], 16) for i in (1, 3, 5))
    # the faded grey mesh covers part of the navy background
    assert _pixels_near(_image(without), navy, 2) > _pixels_near(_image(with_mesh), navy, 2) + 1000


def test_with_a_display_opens_a_window(survey_dir, tmp_path, monkeypatch):
    calls = []
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(point_cloud, "show_point_cloud", lambda xyz, **kw: calls.append((len(xyz), kw)))
    assert _view(survey_dir / "points.las", "--color", "range_error") == 0
    (n, kw), = calls
    assert n == 4000 and kw["color_by"] == "range_error" and kw["scalars"].shape == (4000,)
    assert kw["truth_faces"].shape == (2, 3) and kw["window_size"] == SIZE
    assert not list(survey_dir.glob("*.png"))


def test_show_point_cloud_builds_the_same_plotter_on_screen(monkeypatch):
    import pyvista as pv

    requested, seen = [], []
    init = pv.Plotter.__init__

    def off_screen_init(self, *args, off_screen=None, **kwargs):  # no display here: record, then build off-screen
        requested.append(off_screen)
        init(self, *args, off_screen=True, **kwargs)

    def fake_show(self, title=None, **kwargs):
        seen.append((title, self.window_size, len(self.renderer.actors)))

    monkeypatch.setattr(pv.Plotter, "__init__", off_screen_init)
    monkeypatch.setattr(pv.Plotter, "show", fake_show)
    r = _records(300)
    point_cloud.show_point_cloud(r.xyz, r.classification, title="pass", window_size=SIZE)
    assert requested == [False]
    (title, size, n_actors), = seen
    assert title == "pass" and list(size) == list(SIZE) and n_actors >= 2  # points, legend, title


def test_missing_or_unreadable_file_is_one_line(tmp_path, capsys):
    missing = tmp_path / "nope.las"
    assert _view(missing) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(missing) in err and "no such file" in err
    text = tmp_path / "notes.las"
    text.write_text("not a point cloud\n")
    assert _view(text, "--screenshot", tmp_path / "x.png") == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(text) in err and "not a readable LAS file" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.las"]


def test_bad_colour_is_an_argparse_error(survey_dir, capsys):
    assert _view(survey_dir / "points.las", "--color", "height") == 2  # argparse's error, one line
    err = capsys.readouterr().err
    assert "--color" in err and "'height'" in err and "range_error" in err


def test_a_study_pass_finds_the_scene_one_directory_up(survey_dir, tmp_path, monkeypatch):
    """A coverage study writes scene.ply once at its top and each pass's LAS in a sub-directory."""
    monkeypatch.delenv("DISPLAY", raising=False)
    sub = survey_dir / "clean_ocean-mul2023-6m"
    sub.mkdir(exist_ok=True)
    (sub / "points.las").write_bytes((survey_dir / "points.las").read_bytes())
    found, dropped = tmp_path / "found.png", tmp_path / "dropped.png"
    assert _view(sub / "points.las", "--screenshot", found, "--max-points", "1000") == 0
    assert _view(sub / "points.las", "--screenshot", dropped, "--max-points", "1000", "--no-mesh") == 0
    navy = tuple(int(point_cloud._BACKGROUND[i:i + 2], 16) for i in (1, 3, 5))
    assert _pixels_near(_image(dropped), navy, 2) > _pixels_near(_image(found), navy, 2) + 1000
