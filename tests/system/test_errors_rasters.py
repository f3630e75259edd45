"""Bathymetry rasters that stopped with an internal error, were refused for the wrong reason, or were read wrong
without a word: files GDAL cannot read the pixels of, a large raster under a small survey, CRSs in feet or
degrees, untagged void values, and the class raster in the form docs/scene-format.md shows. Each is either a
seabed that works, or one line naming seabed.raster, the file and what is allowed, exit 2, nothing written."""

import re
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rasterio
from conftest import ROOT
from rasterio.transform import from_origin

from scanner_sim.config import load_scene
from scanner_sim.config.materials import MATERIALS
from scanner_sim.world.scene import build_scene

X0, Y0 = 500_000.0, 5_600_000.0  # UTM zone 31N


def write_raster(path: Path, values: np.ndarray, crs="EPSG:32631", x0=X0, y0=Y0, cell=1.0, **profile):
    """A GeoTIFF of ``values`` (row 0 the northern row), its south-west corner at (x0, y0), square cells."""
    ny, nx = values.shape
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype=values.dtype, crs=crs,
                       transform=from_origin(x0, y0 + ny * cell, cell, cell), **profile) as ds:
        ds.write(values, 1)
    return path


def scene_file(tmp_path: Path, raster: str, platform: str, more: str = "") -> str:
    (tmp_path / "s.yaml").write_text(f"format_version: 1\nname: s\n{more}seabed: {{raster: {raster}}}\n"
                                     f"platform: {platform}\n")
    return "s.yaml"


def track(x0=X0, y0=Y0, unit=1.0) -> str:
    """A straight track 10 to 50 units east of x0, 20 units north of y0, at 4 m altitude."""
    return (f"{{mode: waypoints, altitude_m: 4, waypoints_m: [[{x0 + 10 * unit}, {y0 + 20 * unit}], "
            f"[{x0 + 50 * unit}, {y0 + 20 * unit}]]}}")


def run(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "scanner_sim.cli", *args], capture_output=True, text=True, cwd=tmp_path,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


def refused(tmp_path: Path, scene: str) -> str:
    """`scanner-sim run` of ``scene``: exit 2, one line naming seabed.raster, and nothing written."""
    done = run(tmp_path, "run", scene, "--out", "out", "--max-pulses", "100", "--quiet")
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.strip().splitlines() if not line.startswith("first run:")]
    assert len(lines) == 1 and lines[0].startswith("scanner-sim run: error: seabed.raster = "), lines
    assert not (tmp_path / "out").exists()
    return lines[0]


def bathymetry(shape=(40, 60)) -> np.ndarray:
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return (-12.0 + 0.8 * np.sin(xx / 6.0) + 0.5 * np.cos(yy / 5.0)).astype("float32")


def claim_size(src: Path, dst: Path, width: int, height: int) -> None:
    """A copy of the little-endian classic TIFF ``src`` whose header claims ``width`` x ``height`` pixels (its
    ImageWidth and ImageLength tags rewritten; the pixel data stays what it was)."""
    data = bytearray(src.read_bytes())
    assert data[:4] == b"II*\x00"
    ifd = struct.unpack_from("<I", data, 4)[0]
    for k in range(struct.unpack_from("<H", data, ifd)[0]):
        entry = ifd + 2 + 12 * k
        tag = struct.unpack_from("<H", data, entry)[0]
        if tag in (256, 257):  # ImageWidth, ImageLength, as one LONG each
            struct.pack_into("<HHII", data, entry, tag, 4, 1, width if tag == 256 else height)
    dst.write_bytes(bytes(data))


# -- read errors -------------------------------------------------------------------------------------------------

def test_truncated_geotiff_is_one_line_naming_the_file_and_the_drivers_reason(tmp_path):
    """Root cause: GDAL opens a truncated GeoTIFF (its header is whole) and fails only on reading the pixels, where
    rasterio raises "Read failed. See previous exception for details."; nothing caught it: exit 1 with that line.
    Now the read names seabed.raster, the file and GDAL's own reason."""
    full = write_raster(tmp_path / "full.tif", bathymetry((200, 200)))
    data = full.read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 2])
    line = refused(tmp_path, scene_file(tmp_path, "cut.tif", track()))
    assert "seabed.raster = 'cut.tif': the GTiff driver cannot read its pixels (" in line
    assert "IReadBlock failed" in line and "Read failed" not in line


def test_geotiff_whose_header_claims_60000_x_60000_pixels_is_one_line(tmp_path):
    """A 200 x 200 GeoTIFF whose header claims 60,000 x 60,000 pixels: the survey's window lies in the claimed
    part, the strips there are not in the file: one line naming the file and GDAL's reason, as for a cut file
    (before: exit 1, "Read failed. See previous exception for details.")."""
    write_raster(tmp_path / "small.tif", bathymetry((200, 200)))
    claim_size(tmp_path / "small.tif", tmp_path / "huge.tif", 60_000, 60_000)
    with rasterio.open(tmp_path / "huge.tif") as ds:
        assert (ds.width, ds.height) == (60_000, 60_000)
    line = refused(tmp_path, scene_file(tmp_path, "huge.tif", track(y0=Y0 - 1000)))
    assert "seabed.raster = 'huge.tif': the GTiff driver cannot read its pixels (" in line


# -- sizes from the survey's window ------------------------------------------------------------------------------

def test_2000_x_2000_raster_under_a_50_m_survey_runs_in_under_2_gb(tmp_path):
    """Root cause: the pass budget sized coverage over the raster's whole extent (2,000 x 4 m = 8 km a side, 0.25 m
    cells: 1,024,000,000 cells, 102 GB) and refused the pass, though coverage is tallied over the height field,
    the window the survey reads (the plan and margin_m around it). Now the budget sizes that window: a 50 x 50 m
    lawnmower over the middle of the tile runs, its peak resident memory under 2 GB, measured in the process."""
    n, cell = 2000, 4.0
    yy, xx = np.mgrid[0:n, 0:n]
    write_raster(tmp_path / "tile.tif", (-20.0 + 2.0 * np.sin(xx / 50.0) + 1.5 * np.cos(yy / 70.0)).astype("float32"),
                 cell=cell)
    cx, cy = X0 + n * cell / 2, Y0 + n * cell / 2
    scene_file(tmp_path, "tile.tif", f"{{mode: lawnmower, altitude_m: 5, lawnmower: {{center_m: [{cx}, {cy}], "
               "size_m: [50, 50], line_spacing_m: 5}}", "crs: EPSG:32631\nscanner: {mode: oscillating, sector_deg: 60}\n")
    from scanner_sim.survey.sizing import estimate_pass

    coverage_bytes, _ = estimate_pass(load_scene(tmp_path / "s.yaml")).memory["seabed.raster"]
    assert coverage_bytes < 100e6  # a 100 m window (50 m and 25 m margins) of 0.25 m cells: 0.16 M cells
    # the peak of the child's own address space (VmHWM): getrusage's ru_maxrss keeps, across exec, the resident
    # size of the process it was forked from, here pytest's after a thousand tests (2.5 GiB in a CI run)
    code = ("import re, sys; from pathlib import Path; from scanner_sim.cli import main; code = main(['run', 's.yaml', "
            "'--out', 'out', '--max-pulses', '20000', '--quiet', '--no-render']); "
            "print(re.search(r'VmHWM:\\s+(\\d+) kB', Path('/proc/self/status').read_text())[1]); sys.exit(code)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr
    peak_kib = int(done.stdout.split()[-1])
    assert peak_kib < 2 * 1024 ** 2, f"peak RSS {peak_kib / 1024 ** 2:.2f} GiB"
    assert (tmp_path / "out" / "summary.json").is_file()


# -- units -------------------------------------------------------------------------------------------------------

def test_raster_in_us_survey_feet_is_refused_in_one_line(tmp_path):
    """Root cause: without a scene crs nothing compared the raster's CRS units with the world's metres: a raster
    in NAD83 / New York Long Island (ftUS) was read as metres (4 m cells reported as 13.12 m). Now refused when
    the scene is read, naming the CRS and its unit."""
    foot = 1200.0 / 3937.0  # the US survey foot [m]
    write_raster(tmp_path / "ft.tif", (bathymetry() / foot).astype("float32"), crs="EPSG:2263", x0=1_000_000.0,
                 y0=200_000.0, cell=4.0 / foot)
    line = refused(tmp_path, scene_file(tmp_path, "ft.tif", track(1_000_000.0, 200_000.0, 4.0 / foot)))
    assert "'NAD83 / New York Long Island (ftUS)' is in US survey foot" in line and "in metres" in line
    assert "validate" not in line
    done = run(tmp_path, "validate", "s.yaml")  # refused when read, before any build
    assert done.returncode == 2 and "US survey foot" in done.stderr


def test_raster_in_degrees_without_scene_crs_is_refused_for_its_degrees(tmp_path):
    """Root cause: a raster in WGS 84 degrees read as metres made cells of 1e-5 "m", a track of 0.0004 "m" and a
    pass of 0.00045 s, refused with "the pass fires no pulse", which sent the user to the speed. Now refused
    for what it is: a CRS in degrees, where the world frame is projected in metres."""
    write_raster(tmp_path / "deg.tif", bathymetry(), crs="EPSG:4326", x0=3.0, y0=50.0, cell=1e-5)
    line = refused(tmp_path, scene_file(tmp_path, "deg.tif", track(3.0, 50.0, 1e-5)))
    assert "its CRS 'WGS 84' is geographic (degrees)" in line and "fires no pulse" not in line


# -- void values -------------------------------------------------------------------------------------------------

def test_untagged_void_value_minus_32767_is_refused_naming_the_raster_and_value(tmp_path):
    """Root cause: a void value the file does not tag as nodata (-32767, common in DEM exports) was read as a
    seabed 32,767 m deep; altitude following then took the vehicle 11,814 m under the seabed beside it and the
    message named platform.altitude_m. Now the raster and the value are named, and the nodata key the user
    sets; set, the same raster runs with those pixels as gaps."""
    values = bathymetry()
    values[18:22, 30:33] = -32767.0
    write_raster(tmp_path / "void.tif", values)
    line = refused(tmp_path, scene_file(tmp_path, "void.tif", track()))
    assert "seabed.raster = 'void.tif': 12 of the 2,400 pixels read hold values such as -32767" in line
    assert "deeper than any ocean" in line and "set seabed.nodata: -32767" in line
    (tmp_path / "s.yaml").write_text((tmp_path / "s.yaml").read_text().replace("raster: void.tif",
                                                                               "raster: void.tif, nodata: -32767"))
    scene = build_scene(load_scene(tmp_path / "s.yaml"))
    assert scene.heightfield.valid is not None and scene.heightfield.heights_m.min() > -14.0


@pytest.mark.parametrize("value, sign, where", [(3.4e38, "elevation_up", "higher than any land"),
                                                (32767.0, "depth_down", "deeper than any ocean")])
def test_void_value_is_named_as_the_file_holds_it(tmp_path, value, sign, where):
    """The value named is the file's (a depth raster's 32,767 is its void, not -32,767) and so is the sign rule."""
    values = bathymetry() if sign == "elevation_up" else -bathymetry()
    values[5, 5] = value
    write_raster(tmp_path / "v.tif", values)
    (tmp_path / "s.yaml").write_text(f"format_version: 1\nname: s\nseabed: {{raster: v.tif, vertical: {sign}}}\n"
                                     f"platform: {track()}\n")
    line = refused(tmp_path, "s.yaml")
    assert f"values such as {value:g}" in line and where in line and f"set seabed.nodata: {value:g}" in line


# -- the class raster as documented ------------------------------------------------------------------------------

def test_class_raster_as_docs_scene_format_shows_works(tmp_path):
    """Root cause: the scene loader refuses keys that are not text, and the class raster's materials table is
    keyed by the integer codes of its pixels, as docs/scene-format.md writes it ({1: {material: rock}, ...}):
    "key 1 is not text". The page's example block, its classes line uncommented, over the shipped real-site
    raster it names and a class raster of codes 1 (west half) and 2 (east half): each seabed cell takes its
    code's material."""
    doc = (ROOT / "docs" / "scene-format.md").read_text()
    block = doc.split("## Seabed from a bathymetry raster", 1)[1].split("```text\n", 1)[1].split("```", 1)[0]
    block, uncommented = re.subn(r"^(\s*)# (classes:)", r"\1\2", block, flags=re.M)
    assert uncommented == 1
    (tmp_path / "assets" / "real_site").mkdir(parents=True)
    shutil.copy(ROOT / "scenes" / "assets" / "real_site" / "H12607_deep.tif", tmp_path / "assets" / "real_site")
    with rasterio.open(tmp_path / "assets" / "real_site" / "H12607_deep.tif") as ds:
        profile, (ny, nx), west, east = ds.profile, ds.shape, ds.bounds.left, ds.bounds.right
    codes = np.ones((ny, nx), "uint8")
    codes[:, nx // 2:] = 2
    profile.update(dtype="uint8", nodata=0)
    with rasterio.open(tmp_path / "classes.tif", "w", **profile) as ds:
        ds.write(codes, 1)
    middle = west + (nx // 2) * (east - west) / nx  # where code 1 gives way to code 2
    (tmp_path / "s.yaml").write_text("format_version: 1\nname: classes\n" + block +
                                     "platform: {mode: static, position_m: [614200, 4494784], altitude_m: 4}\n"
                                     "survey: {max_pulses: 100}\n")
    scene = build_scene(load_scene(tmp_path / "s.yaml"))
    seabed = scene.objects[0]
    reflectance = scene.face_reflectance[seabed.face_start:seabed.face_stop]
    centre_x = scene.vertices[scene.faces[seabed.face_start:seabed.face_stop]].mean(axis=1)[:, 0]
    assert np.all(reflectance[centre_x < middle - 1] == MATERIALS["rock"].reflectance)
    assert np.all(reflectance[centre_x > middle + 1] == 0.3)
