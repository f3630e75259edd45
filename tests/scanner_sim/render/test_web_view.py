"""scanner-sim view RUN_DIR --html: one self-contained WebGL page of a pass, checked in headless Chromium
(SwiftShader WebGL, networking off), and its budgets, mesh clustering and dropout footprints."""

from __future__ import annotations

import base64
import json
import math
import re
import shutil
import subprocess
from html.parser import HTMLParser

import laspy
import numpy as np
import pytest
from conftest import chromium

from scanner_sim import cli, io
from scanner_sim.records.point_records import DropoutRecords
from scanner_sim.render import web_view
from scanner_sim.render.point_colours import CLASS_COLOURS

WINDOW = (1200, 800)
BACKGROUND = (0x0B, 0x1A, 0x2A)


@pytest.fixture(scope="module")
def pass_dir(tmp_path_factory):
    """A 20,000-pulse cable_survey pass and its page, view.html."""
    out = tmp_path_factory.mktemp("web") / "cable"
    assert cli.main(["run", "cable_survey", "--max-pulses", "20000", "--no-render", "--quiet", "--out", str(out)]) == 0
    assert cli.main(["view", str(out), "--html"]) == 0
    return out


def _offline() -> list[str]:
    """A command prefix that runs Chromium with networking off: a network namespace of its own (no interface but
    a down loopback) where the kernel lets us make one, else a proxy and resolver that reach nothing."""
    unshare = shutil.which("unshare")
    if unshare and subprocess.run([unshare, "-n", "true"], capture_output=True).returncode == 0:
        return [unshare, "-n"]
    return []


def _browse(page, tmp_path, fragment: str, *, screenshot=None) -> subprocess.CompletedProcess:
    """Chromium, headless with SwiftShader WebGL and no network, on ``page#fragment``: a screenshot, or the DOM."""
    profile = tmp_path / f"profile-{len(list(tmp_path.glob('profile-*')))}"
    args = [*_offline(), chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader", "--disable-background-networking", "--proxy-server=http://127.0.0.1:9",
            "--host-resolver-rules=MAP * ~NOTFOUND", f"--user-data-dir={profile}", "--hide-scrollbars",
            f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=20000",
            f"--screenshot={screenshot}" if screenshot else "--dump-dom", f"{page.as_uri()}#{fragment}"]
    run = subprocess.run(args, capture_output=True, text=True, timeout=240)
    assert run.returncode == 0, run.stderr[-2000:]
    return run


def _shot(page, tmp_path, fragment: str) -> np.ndarray:
    from matplotlib import image as mpimg

    png = tmp_path / f"{fragment.replace('=', '-').replace('&', '_')}.png"
    _browse(page, tmp_path, fragment, screenshot=png)
    return (mpimg.imread(png)[..., :3] * 255).round().astype(np.int16)


def _near(img: np.ndarray, rgb, tol: int = 10) -> int:
    return int(np.all(np.abs(img - np.asarray(rgb)) <= tol, axis=-1).sum())


def test_chromium_draws_the_pass_and_depth_colouring_changes_it(pass_dir, tmp_path):
    """Offline, the page draws its first frames; coloured by class the seabed is sand, coloured by depth it is not
    (viridis instead); the right 3/4 of the window (clear of the panel) holds the picture."""
    page = pass_dir / "view.html"
    by_class = _shot(page, tmp_path, "color=class")
    by_depth = _shot(page, tmp_path, "color=depth")
    for img in (by_class, by_depth):
        assert img.shape == (WINDOW[1], WINDOW[0], 3)
        scene = img[:, WINDOW[0] // 4:]
        drawn = ~np.all(np.abs(scene - BACKGROUND) <= 6, axis=-1)
        assert drawn.mean() > 0.10  # not blank: points and the faded mesh cover a tenth of it at least
    sand = CLASS_COLOURS["seabed"]
    assert _near(by_class, sand) > 2000
    assert _near(by_depth, sand) < _near(by_class, sand) / 20
    changed = np.any(np.abs(by_class - by_depth) > 30, axis=-1)
    assert changed.sum() > 5000
    dom = _browse(page, tmp_path, "color=depth").stdout
    assert re.search(r'<span id="shown-colour">depth</span>', dom)
    assert int(re.search(r'<span id="frames">(\d+)</span>', dom)[1]) >= 1


def test_page_count_is_the_file_count_and_opens_offline(pass_dir, tmp_path):
    dom = _browse(pass_dir / "view.html", tmp_path, "").stdout
    with laspy.open(pass_dir / "points.las") as f:
        n = f.header.point_count
    assert n < web_view.DEFAULT_MAX_POINTS
    assert f'data-count="{n}"' in dom and f"all {n:,} points" in dom
    assert 'data-ready="1"' in dom  # the viewer ran to its end, with no network


class _Refs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.refs = []

    def handle_starttag(self, tag, attrs):
        self.refs += [(tag, k, v) for k, v in attrs if k in ("src", "href")]


def test_page_refers_to_nothing_outside_itself(pass_dir):
    text = (pass_dir / "view.html").read_text(encoding="utf-8")
    refs = _Refs()
    refs.feed(text)
    assert refs.refs == []
    assert "three.js authors" in text.lower()  # the licence notice travels with the bundled library
    assert re.search(r"\bfetch\(|XMLHttpRequest|import\(", text.split('id="muls-data"')[1]) is None


def _data(path) -> dict:
    text = path.read_text(encoding="utf-8")
    return json.loads(re.search(r'<script type="application/json" id="muls-data">(.*?)</script>', text, re.S)[1])


def _decode(spec) -> np.ndarray:
    return np.frombuffer(base64.b64decode(spec["b64"]), dtype={"u1": "<u1", "u4": "<u4", "f4": "<f4"}[spec["dtype"]])


def test_a_large_pass_is_thinned_by_the_stated_rule(pass_dir, tmp_path, capsys):
    out = tmp_path / "small.html"
    assert cli.main(["view", str(pass_dir), "--html", str(out), "--max-points", "3000"]) == 0
    n = len(io.read_las(pass_dir / "points.las"))
    k = math.ceil(n / 3000)
    data = _data(out)
    positions = _decode(data["points"]["positions"]).reshape(-1, 3)
    assert data["stride"] == k and len(positions) == len(range(0, n, k)) <= 3000
    assert f"one point in every {k} in file order" in data["sampling"]
    assert f"{len(positions):,} of {n:,}" in capsys.readouterr().out
    full = io.read_las(pass_dir / "points.las").xyz[::k]  # every k-th point, from the first
    assert np.allclose(positions + np.asarray(data["centre_m"]), full, atol=1e-3)


def test_default_colouring_is_depth_over_a_seabed_and_class_without(pass_dir, tmp_path):
    assert _data(pass_dir / "view.html")["default_color"] == "depth"
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(pass_dir / "points.las", bare / "points.las")  # no scene.ply: nothing says there is a seabed
    assert cli.main(["view", str(bare), "--html"]) == 0
    data = _data(bare / "view.html")
    assert data["default_color"] == "class" and data["mesh"] is None


def test_mesh_clustering_keeps_the_surface_within_budget():
    """A 100 x 100 m gentle wave surface of 80,000 triangles, clustered to 5,000: it fits, covers the same plan,
    and every merged vertex stays on the surface to within the wave's change over one grid cell."""
    x, y = np.meshgrid(np.linspace(0, 100, 201), np.linspace(0, 100, 201))
    z = np.sin(x / 15.0) * np.cos(y / 20.0)
    vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    i = np.arange(200)[:, None] * 201 + np.arange(200)[None, :]
    faces = np.r_[np.column_stack([i.ravel(), i.ravel() + 1, i.ravel() + 202]),
                  np.column_stack([i.ravel(), i.ravel() + 202, i.ravel() + 201])]
    v, f = web_view.cluster_mesh(vertices, faces, 5000)
    assert 1000 < len(f) <= 5000 and f.max() < len(v)
    assert np.allclose(v[:, :2].min(axis=0), 0, atol=3) and np.allclose(v[:, :2].max(axis=0), 100, atol=3)
    cell = math.sqrt(2 * 100 * 100 / 5000) * 1.25 ** 3
    surface = np.sin(v[:, 0] / 15.0) * np.cos(v[:, 1] / 20.0)
    assert np.abs(v[:, 2] - surface).max() < cell / 15.0  # the steepest slope is 1/15


def test_dropouts_are_drawn_at_their_beams_footprint_by_cause(pass_dir, tmp_path):
    """Beams from 6 m above a flat seabed at z = -25 m, aimed down at 30 degrees: each is drawn where its axis meets
    the seabed; one aimed up meets nothing and is only counted."""
    folder = tmp_path / "drops"
    folder.mkdir()
    shutil.copy(pass_dir / "points.las", folder / "points.las")
    plane = np.array([[-50, -50, -25], [50, -50, -25], [50, 50, -25], [-50, 50, -25]], float)
    io.write_scene_ply(folder / "scene.ply", plane, np.array([[0, 1, 2], [0, 2, 3]]), [40, 40], [0, 0])
    a = math.radians(30)
    direction = np.array([[math.sin(a), 0, -math.cos(a)], [0, -math.sin(a), -math.cos(a)], [0, 0, 1]], np.float32)
    origin = np.array([[0, 0, -19], [3, 4, -19], [0, 0, -19]], float)
    io.write_dropouts_npz(folder / "dropouts.npz", DropoutRecords(
        pulse_index=np.arange(3), time_s=np.zeros(3), origin=origin, direction=direction,
        cause=np.array([2, 4, 0], np.uint8)))
    data = web_view.page_data(web_view.PassFiles.of(folder))
    drawn = _decode(data["dropouts"]["positions"]).reshape(-1, 3) + np.asarray(data["centre_m"])
    run = 6 * math.tan(a)
    assert np.allclose(drawn, [[run, 0, -25], [3, 4 - run, -25]], atol=1e-3)
    assert list(_decode(data["dropouts"]["cause"])) == [2, 4]
    assert data["dropouts"]["drawn"] == {"below_threshold": 1, "masked_by_backscatter": 1}
    assert "1 whose beam meets no surface are not drawn" in data["notes"][1]


def test_a_folder_without_points_is_one_line(tmp_path, capsys):
    assert cli.main(["view", str(tmp_path), "--html"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(tmp_path) in err and "no points.las" in err
    assert not (tmp_path / "view.html").exists()
