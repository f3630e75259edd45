"""What a surveyor reads first, said right: validate's CRS check, the console's dropout line, the summary's
calibration note, the progress bar's total on tiled sites, and the coverage report's labels and notes."""

import yaml

from scanner_sim.cli import main
from tests.test_raster_seabed import X0, Y0, bathymetry, write_raster


def _raster_scene_file(tmp_path, crs: str):
    write_raster(tmp_path / "site.tif", bathymetry())  # UTM zone 31N
    data = {"format_version": 1, "name": "raster_site", "crs": crs, "water": "clean_ocean",
            "seabed": {"raster": "site.tif"},
            "platform": {"mode": "waypoints", "altitude_m": 4.0,
                         "waypoints_m": [[X0 + 10, Y0 + 20], [X0 + 50, Y0 + 20]]},
            "survey": {"max_pulses": 2000}}
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_validate_refuses_a_raster_in_another_crs_with_runs_line(tmp_path, capsys):
    """`scanner-sim validate` said OK for a raster in UTM 31N under crs: EPSG:32632; only `run` refused it. Root
    cause: the raster's CRS was checked only when the seabed was built, which validate (without --build) skips.
    Now validate runs the same check from the raster's header: exit 2, the same one line as run, nothing written."""
    path = _raster_scene_file(tmp_path, "EPSG:32632")
    assert main(["validate", str(path)]) == 2
    validate_err = capsys.readouterr().err.strip()
    assert "seabed.raster = 'site.tif': its CRS (WGS 84 / UTM zone 31N) is not the scene's crs" in validate_err
    assert len(validate_err.splitlines()) == 1
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    run_err = capsys.readouterr().err.strip().splitlines()[-1]
    assert run_err.split(": error: ", 1)[1] == validate_err.split(": error: ", 1)[1]
    assert not out.exists()


def test_validate_accepts_the_raster_in_the_scenes_crs(tmp_path, capsys):
    assert main(["validate", str(_raster_scene_file(tmp_path, "EPSG:32631"))]) == 0
    assert capsys.readouterr().out.startswith("OK raster_site")
