"""Every key of the scene's ``output`` section changes what a pass writes; survey legs; the LAS conventions
of a real pass read back with laspy."""

import json

import laspy
import numpy as np
import pytest

from scanner_sim.cli import main
from scanner_sim.config import load_scene
from scanner_sim.io import read_las_metadata, read_waveforms_npz
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions

PULSES = 1500


def _run(tmp_path, **output):
    config = load_scene("cable_survey").with_overrides({f"output.{k}": v for k, v in output.items()})
    run_pass(config, tmp_path, PassOptions(max_pulses=PULSES, progress=False, render=False, write_scene=False))
    return {p.name for p in tmp_path.iterdir()}


def test_the_defaults_write_las_and_trajectory(tmp_path):
    files = _run(tmp_path)
    assert {"points.las", "trajectory.csv", "dropouts.npz", "summary.json"} <= files
    assert "points.laz" not in files and "waveforms.npz" not in files


def test_output_las_false_writes_no_las(tmp_path):
    assert "points.las" not in _run(tmp_path, las=False)


def test_output_laz_writes_a_compressed_cloud_with_the_same_points(tmp_path):
    files = _run(tmp_path, laz=True)
    assert {"points.las", "points.laz"} <= files
    las, laz = laspy.read(tmp_path / "points.las"), laspy.read(tmp_path / "points.laz")
    assert laz.header.point_count == las.header.point_count > 0
    np.testing.assert_array_equal(laz.X, las.X)
    assert (tmp_path / "points.laz").stat().st_size < 0.5 * (tmp_path / "points.las").stat().st_size


def test_output_trajectory_csv_false_writes_no_trajectory(tmp_path):
    assert "trajectory.csv" not in _run(tmp_path, trajectory_csv=False)


def test_output_waveform_every_n_pulses_keeps_every_nth_fired_pulse(tmp_path):
    _run(tmp_path, waveform_every_n_pulses=100)
    pulse_index, time_ns, channels = read_waveforms_npz(tmp_path / "waveforms.npz")
    assert len(pulse_index) == PULSES // 100
    assert set(channels) == {"ch0", "ch1", "ch2", "ch3"} and channels["ch1"].shape[0] == len(pulse_index)


def test_output_dir_is_where_a_pass_writes_without_out(tmp_path):
    config = load_scene("pool_panel").with_overrides({"output.dir": str(tmp_path / "here"), "survey.max_pulses": 20})
    result = run_pass(config, options=PassOptions(progress=False, render=False))
    assert result.out_dir == tmp_path / "here" and (tmp_path / "here" / "summary.json").is_file()


def test_split_lines_writes_one_laz_per_leg_with_its_source_id_metadata_and_channels(tmp_path, capsys):
    """The acceptance command, on a faster AUV so that 40,000 pulses cross three legs (line, turn, line)."""
    out = tmp_path / "legs"
    code = main(["run", "seabed_lawnmower", "--split-lines", "--out", str(out), "--max-pulses", "40000",
                 "--set", "platform.speed_m_s=10", "--no-render", "--quiet"])
    assert code == 0
    clouds = sorted(out.glob("leg*_points.laz"))
    assert len(clouds) >= 3 and not (out / "points.laz").exists()
    ids = []
    for path in clouds:
        las = laspy.read(path)
        assert las.header.point_count > 0
        (leg,) = np.unique(las.point_source_id)
        assert las.header.file_source_id == leg == int(path.name[3:6])
        ids.append(int(leg))
        meta = read_las_metadata(path)["pass_metadata"]
        assert meta["scene"] == "seabed_lawnmower" and meta["seed"] == 3 and meta["muls_scanner_version"]
        assert {"water", "instrument", "fidelity"} <= set(meta)
        np.testing.assert_array_equal(las.scanner_channel, las.channel)  # the MUL's channels fit 2 bits
        assert np.all(las.synthetic == 1)
    assert len(set(ids)) == len(ids)
    assert sorted(out.glob("leg*_trajectory.csv"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["points"] == sum(laspy.read(p).header.point_count for p in clouds)


@pytest.mark.parametrize("value", ["x", "=3", "platform.altitude_m"])
def test_a_bad_set_is_one_line_and_exit_2(value, capsys):
    assert main(["run", "pool_panel", "--set", value, "--quiet", "--no-render"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
