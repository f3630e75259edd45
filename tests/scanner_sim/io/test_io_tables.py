"""The other output files: atomic writes, dropouts.npz (streamed), summary.json, trajectory.csv,
waveforms.npz, coverage_grid.npz."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from scanner_sim import io
from scanner_sim.metrics.coverage import GAP_CAUSES, PlanGrid
from scanner_sim.records.point_records import DROPOUT_CAUSES, DropoutRecords


def make_dropouts(n: int = 300, seed: int = 1, first_pulse: int = 0) -> DropoutRecords:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return DropoutRecords(
        pulse_index=first_pulse + np.arange(n),
        time_s=(first_pulse + np.arange(n)) * 2e-4,
        origin=rng.uniform(-100, 100, (n, 3)),
        direction=d / np.linalg.norm(d, axis=1, keepdims=True),
        cause=rng.integers(0, len(DROPOUT_CAUSES), n),
    )


class Boom(Exception):
    pass


def test_dropout_records_concatenate_empty_and_cause_codes():
    assert len(DropoutRecords.empty()) == 0
    d = DropoutRecords.concatenate([make_dropouts(3), make_dropouts(4)])
    assert len(d) == 7 and sum(d.counts_by_cause().values()) == 7
    with pytest.raises(ValueError, match="code 6 is unknown"):
        DropoutRecords(**{**make_dropouts(2).as_dict(), "cause": np.array([0, 6])})


def test_other_writers_are_atomic_on_error(tmp_path):
    with pytest.raises(ValueError, match="not JSON-serialisable"):
        io.write_summary_json(tmp_path / "summary.json", {"x": object()})
    with pytest.raises(ValueError, match="channels"):
        io.write_waveforms_npz(tmp_path / "w.npz", [1], np.arange(4.0), {"time_ns": np.zeros((1, 4))})
    with pytest.raises(Boom), io.DropoutWriter(tmp_path / "dropouts.npz") as w:
        w.write(make_dropouts(10))
        raise Boom
    assert os.listdir(tmp_path) == []


def test_dropouts_npz_round_trip_and_streaming(tmp_path):
    chunks = [make_dropouts(200, seed=s, first_pulse=500 * s) for s in range(3)]
    whole = DropoutRecords.concatenate(chunks)
    io.write_dropouts_npz(tmp_path / "once.npz", whole)
    with io.DropoutWriter(tmp_path / "stream.npz") as w:
        for c in chunks:
            w.write(c)
    assert w.counts_by_cause() == whole.counts_by_cause()
    assert sorted(os.listdir(tmp_path)) == ["once.npz", "stream.npz"]  # spool removed
    for name in ("once.npz", "stream.npz"):
        back = io.read_dropouts_npz(tmp_path / name)
        for field in DropoutRecords.field_names():
            np.testing.assert_array_equal(getattr(back, field), getattr(whole, field), err_msg=field)
    with np.load(tmp_path / "stream.npz") as z:
        assert tuple(z["cause_names"]) == DROPOUT_CAUSES
    with io.DropoutWriter(tmp_path / "none.npz"):
        pass
    assert len(io.read_dropouts_npz(tmp_path / "none.npz")) == 0


def test_summary_json_converts_numpy(tmp_path):
    summary = {"scene": "cable_survey", "seed": np.int64(3), "pulses_per_s": np.float32(5.5e4),
               "dropouts": {"no_hit": np.uint32(2)}, "range_error_m": {"median": np.nan},
               "bbox": np.array([1.0, 2.0]), "flag": np.bool_(True)}
    io.write_summary_json(tmp_path / "summary.json", summary)
    text = (tmp_path / "summary.json").read_text()
    back = json.loads(text)
    assert list(back) == list(summary)  # insertion order, not sorted
    assert back["seed"] == 3 and back["dropouts"]["no_hit"] == 2 and back["flag"] is True
    assert back["range_error_m"]["median"] is None and back["bbox"] == [1.0, 2.0]
    assert '\n  "scene"' in text


def test_trajectory_csv_round_trip(tmp_path):
    n = 50
    t = np.linspace(0, 10, n)
    pos = np.column_stack([t * 1.5 + 500000.0, np.zeros(n), np.full(n, -20.0)])
    rpy = np.column_stack([np.zeros(n), np.ones(n), np.full(n, 90.0)])
    io.write_trajectory_csv(tmp_path / "trajectory.csv", t, pos, rpy,
                            estimated_position_m=pos + 0.01, estimated_attitude=rpy + 0.1)
    first = (tmp_path / "trajectory.csv").read_text().splitlines()[0]
    assert first.startswith("time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg,est_x_m")
    back = io.read_trajectory_csv(tmp_path / "trajectory.csv")
    np.testing.assert_allclose(back["x_m"], pos[:, 0], atol=1e-6)
    np.testing.assert_allclose(back["est_yaw_deg"], 90.1)
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    io.write_trajectory_csv(tmp_path / "q.csv", t, pos, q, attitude_format="quaternion")
    assert set(io.read_trajectory_csv(tmp_path / "q.csv")) >= {"qw", "qx", "qy", "qz"}
    with pytest.raises(ValueError, match="attitude: shape"):
        io.write_trajectory_csv(tmp_path / "bad.csv", t, pos, q)


def test_waveforms_npz_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    ch = {f"ch{i}": rng.integers(0, 1024, (3, 400)).astype(np.uint16) for i in range(4)}
    io.write_waveforms_npz(tmp_path / "waveforms.npz", [5, 9, 12], np.arange(400.0), ch)
    pi, t, back = io.read_waveforms_npz(tmp_path / "waveforms.npz")
    np.testing.assert_array_equal(pi, [5, 9, 12])
    assert t.shape == (400,) and list(back) == list(ch)
    for name, data in ch.items():
        np.testing.assert_array_equal(back[name], data)
        assert back[name].dtype == np.uint16
    with pytest.raises(ValueError, match=r"channels\['ch1'\]: shape"):
        io.write_waveforms_npz(tmp_path / "w.npz", [1], np.arange(4.0), {"ch1": np.zeros((2, 4))})


def test_coverage_grid_npz_round_trip(tmp_path):
    grid = PlanGrid(origin_m=(10.0, -5.0), cell_m=0.25, shape=(2, 3))
    state = np.array([[-2, -1, 0], [1, -1, -2]])
    io.write_coverage_grid_npz(tmp_path / "coverage_grid.npz", grid, state, np.arange(6), np.arange(6) // 2)
    back = io.read_coverage_grid_npz(tmp_path / "coverage_grid.npz")
    np.testing.assert_array_equal(back["state"], state)
    assert back["state"].dtype == np.int16 and back["reaching"].shape == (2, 3)
    assert tuple(back["gap_cause_names"]) == GAP_CAUSES and float(back["cell_m"]) == 0.25
    with pytest.raises(ValueError, match="valid: 5 cells"):
        io.write_coverage_grid_npz(tmp_path / "x.npz", grid, state, np.arange(6), np.arange(5))
    assert sorted(os.listdir(tmp_path)) == ["coverage_grid.npz"]
