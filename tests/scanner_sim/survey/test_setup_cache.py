"""The set-up's ranging-precision table kept between runs (scanner_sim/survey/setup_cache.py): the same inputs read it
back, any changed input measures it again, and a damaged entry is measured again and replaced, never trusted."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from scanner_sim.survey import setup_cache
from scanner_sim.survey.ranging_precision import RangingPrecision


@pytest.fixture
def measured(tmp_path, monkeypatch):
    """The cache under ``tmp_path``; the measurement replaced by one that counts its calls and whose table depends on
    the physics' seed and the ranges (so a wrong entry read back would show)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    calls = []

    def measure(physics, instrument, ranges_m):
        calls.append((physics.seed, tuple(ranges_m)))
        shape = (3, 2, 2, len(ranges_m), 24)
        bias = np.random.default_rng(physics.seed).normal(0.0, 0.01, shape)
        return RangingPrecision(bias, np.abs(bias), np.full(shape, 20), np.geomspace(1.0, 1e6, 25), tuple(ranges_m))

    monkeypatch.setattr(setup_cache, "measure_ranging_precision", measure)
    return calls


def physics(seed: int = 7, record_mode: str = "ch0_peak"):
    model = SimpleNamespace(instrument="inst", water=("coastal", 0.3), multiple_scattering="table",
                            tables=np.arange(5.0), attenuation=None, scattering=None)
    return SimpleNamespace(model=model, seed=seed, record_mode=record_mode, deciding_only=True)


def same(a: RangingPrecision, b: RangingPrecision) -> bool:
    return (a.ranges_m == b.ranges_m and all(np.array_equal(getattr(a, f), getattr(b, f))
                                            for f in ("bias_m", "std_m", "count", "snr_edges")))


def test_the_same_inputs_read_the_table_back(measured):
    first = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    again = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert measured == [(7, (2.0, 3.5))] and same(first, again)


@pytest.mark.parametrize("changed", [dict(seed=8), dict(record_mode="full"), dict(ranges=(2.0, 3.6)),
                                     dict(tables=np.arange(5.0) + 1e-12)])
def test_a_changed_input_misses(measured, changed):
    setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    other = physics(changed.get("seed", 7), changed.get("record_mode", "ch0_peak"))
    if "tables" in changed:
        other.model.tables = changed["tables"]
    table = setup_cache.cached_ranging_precision(other, "inst", changed.get("ranges", (2.0, 3.5)))
    assert len(measured) == 2
    assert table.ranges_m == changed.get("ranges", (2.0, 3.5))


def test_a_damaged_entry_is_measured_again_and_replaced(measured):
    first = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    (entry,) = setup_cache.tables_dir().rglob("ranging_*.npz")
    data = bytearray(entry.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 8] = bytes(8 * [0xFF])  # inside the stored arrays: only the zip's CRC can tell
    entry.write_bytes(bytes(data))
    again = setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert len(measured) == 2 and same(first, again)
    entry.write_bytes(b"")  # truncated to nothing
    setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert len(measured) == 3
    setup_cache.cached_ranging_precision(physics(), "inst", (2.0, 3.5))
    assert len(measured) == 3  # replaced by a good entry


def test_an_unwritable_cache_measures_each_time(measured, tmp_path, monkeypatch):
    (tmp_path / "file").write_text("not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "file"))
    for _ in range(2):
        assert setup_cache.cached_ranging_precision(physics(), "inst", (2.0,)).ranges_m == (2.0,)
    assert len(measured) == 2
