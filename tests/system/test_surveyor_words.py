"""What a surveyor reads first, said right: validate's CRS check, the console's dropout line, the summary's
calibration note, the progress bar's total on tiled sites, and the coverage report's labels and notes."""

import yaml

from scanner_sim.cli import main
from tests.scanner_sim.world.test_raster_seabed import X0, Y0, bathymetry, write_raster


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


def _record(instrument, covered, valid, gaps):
    causes = dict.fromkeys(("no_hit", "blind_zone", "below_threshold", "saturated", "masked_by_backscatter",
                            "outside_gate", "out_of_tolerance", "other_surface"), 0.0)
    return {"water": "turbid_harbor", "altitude_m": 4.0, "instrument": instrument, "covered_fraction": covered,
            "reached_area_m2": 40.0, "valid_points_in_reach": valid, "gaps_m2": {**causes, **gaps}}


def test_multichannel_table_gives_percentage_points_beside_percentages_and_says_why_mul2023_covers_less():
    """The report put "difference [points]" (a difference of valid point counts, -2,346) beside two covered
    percentages, and said nothing of why mul2023 covers less than single_channel in turbid water at 4 m. Root
    cause: one column mixed two units and the table had no note. Hand case: 67.5 % against 72.5 % covered, 12 of
    40 m² masked by backscatter for mul2023, 11 m² below threshold for single_channel."""
    from scanner_sim.render.report import multichannel_notes, multichannel_table

    study = {"records": [_record("mul2023", 0.675, 12_000, {"masked_by_backscatter": 12.0}),
                         _record("single_channel", 0.725, 14_346, {"below_threshold": 11.0})]}
    header, (row,) = multichannel_table(study)
    cells = dict(zip(header, row))
    assert cells["covered, mul2023 − single_channel [percentage points]"] == "-5.0"
    assert cells["valid points, mul2023 − single_channel"] == "-2,346"
    assert cells["masked by backscatter, mul2023 / single_channel [% of reached]"] == "30.0 / 0.0"
    assert not any(h.endswith("[points]") for h in header)
    (note,) = multichannel_notes(study)
    assert "masks the echo on 30.0 % of mul2023's reached area" in note
    assert "single_channel loses 27.5 % to below threshold" in note
    study["records"][0]["covered_fraction"] = 0.8  # mul2023 ahead: nothing to explain
    assert multichannel_notes(study) == []


def test_progress_total_is_the_pulses_real_site_fires():
    """real_site's progress bar ran past its total (393,750 pulses fired under a total of 391k). Root cause: the
    total was the slots times sector / 360 deg (a quarter for 90 deg), while a slot on the sector's edge fires or
    not by rounding: 126 of every 500 slots fire, not 125. Now the total counts the firing slots by the same test
    pulse_slots uses."""
    from scanner_sim.config import load_scene
    from scanner_sim.survey.setup import PassOptions, PassSetup

    setup = PassSetup.build(load_scene("real_site"), PassOptions(progress=False))
    fired = sum(slots.size for slots in setup.slot_chunks())
    assert fired == 393_750
    assert setup.expected_pulses() == fired


def test_console_names_the_rasters_nodata_behind_the_no_hit_dropouts(tmp_path, capsys):
    """real_site's console read "dropouts: no_hit 46,559" with no word that these beams were aimed at the
    raster's nodata, where there is no seabed to meet. Root cause: nothing compared a no_hit beam with where the
    seabed has data. Hand case: a flat seabed 12 m deep whose western half is nodata (-9999), flown across the
    boundary at 4 m in clean water: every beam over the data meets it, so every no_hit is aimed at the nodata."""
    import json

    import numpy as np

    values = np.full((40, 60), -12.0)
    values[:, :30] = -9999.0
    write_raster(tmp_path / "site.tif", values, nodata=-9999.0)
    data = {"format_version": 1, "name": "half_nodata", "crs": "EPSG:32631", "water": "clean_ocean",
            "seabed": {"raster": "site.tif"},
            "platform": {"mode": "waypoints", "altitude_m": 4.0,
                         "waypoints_m": [[X0 + 24, Y0 + 20], [X0 + 36, Y0 + 20]]},
            "survey": {"max_pulses": 6000}}
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-render"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    no_hit = summary["dropouts"]["no_hit"]
    assert no_hit > 500
    assert summary["no_hit_over_no_seabed"] == no_hit
    console = capsys.readouterr().out
    assert f"no_hit {no_hit:,} ({no_hit:,} of them aimed where the raster has nodata (-9999)" in console


def test_summary_calibration_says_one_short_pass_is_one_draw_of_the_navigation_drift():
    """The summary gave horizontal_within_thu 0.79 with no word that one short pass is one draw of the navigation's
    drift (cable_survey's noise is correlated over 20 s; its oscillating scanner fires every slot, so 3,000 pulses
    at 5 kHz fly 0.6 s). Root cause: the calibration block carried the shares alone."""
    import scanner_sim
    from scanner_sim.config import load_scene

    config = load_scene("cable_survey")
    summary = scanner_sim.simulate_pass(config, scanner_sim.PassOptions(max_pulses=3000, progress=False)).summary
    note = summary["uncertainty"]["calibration"]["note"]
    tau = config.platform.navigation_noise.correlation_time_s
    assert "one pass of 0.6 s" in note and f"correlated over {tau:g} s" in note and "about one draw" in note
    assert "--seeds N" in note


def test_the_reports_s44_words_say_what_each_orders_figure_does_not_check():
    """The coverage report showed Exclusive at 98.8 % without saying that its 200 % coverage and its feature search
    are not checked. Root cause: the report's S-44 text described the compliance rule alone."""
    from scanner_sim.render.report import _s44_text, compliance_table

    study = {"study": {"order_min_soundings": 5}, "s44_source": "IHO S-44",
             "s44_orders": {"exclusive": {}, "2": {}},
             "records": [{"water": "w", "instrument": "i", "altitude_m": 4.0, "planned_swath": None,
                          "range_error_m": {"median": None},
                          "orders": {"exclusive": {"cell_m": 0.5, "compliant_fraction": 0.988},
                                     "2": {"cell_m": 20.0, "compliant_fraction": 1.0}}}]}
    text = _s44_text(study)
    assert "Not checked: Exclusive's 200 % coverage" in text and "feature search" in text
    assert "Orders 1b and 2, which ask no feature detection" in text
    header, _ = compliance_table(study)
    assert "exclusive [%] (0.5 m cells)" in header and "2 [%] (20 m cells)" in header
