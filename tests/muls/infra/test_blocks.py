"""A batch cut into blocks on threads (muls/infra/blocks.py): the blocks cover the batch, and a batch simulated in
blocks is the same bytes as in one (records, peaks, returns, dropouts)."""

import dataclasses

import numba
import numpy as np
import pytest
from conftest import detection_model

from muls.infra import blocks
from muls.optics.optical_model import PulseBatch
from muls.simulate import simulate


def test_blocks_cover_the_batch_once_in_order(monkeypatch):
    monkeypatch.setattr(numba, "get_num_threads", lambda: 3)
    bounds = blocks.block_bounds(10 * blocks.MIN_BLOCK + 1)
    assert bounds[0] == 0 and bounds[-1] == 10 * blocks.MIN_BLOCK + 1 and len(bounds) == 4
    assert np.all(np.diff(bounds) >= blocks.MIN_BLOCK)
    assert blocks.in_blocks(lambda a, b: (a, b), 10 * blocks.MIN_BLOCK + 1) == list(zip(bounds[:-1], bounds[1:]))
    assert blocks.block_bounds(blocks.MIN_BLOCK + 1).tolist() == [0, blocks.MIN_BLOCK + 1]  # too small to cut


def test_one_numba_thread_means_one_block():
    numba.set_num_threads(1)
    try:
        assert blocks.block_bounds(100 * blocks.MIN_BLOCK).tolist() == [0, 100 * blocks.MIN_BLOCK]
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def _arrays(result):
    """Every array of a (Waveforms, Ranging) pair, by name."""
    out = {}
    for prefix, obj in zip(("records", "ranging"), result):
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if dataclasses.is_dataclass(value):
                out |= {f"{prefix}.{f.name}.{g.name}": getattr(value, g.name) for g in dataclasses.fields(value)}
            elif isinstance(value, np.ndarray):
                out[f"{prefix}.{f.name}"] = value
    return out


@pytest.mark.parametrize("options", [dict(mode="windowed"), dict(mode="windowed", deciding_only=True),
                                     dict(mode="full", keep_noise_free=True), dict(mode="full", ranging_only=True)])
def test_a_batch_in_blocks_is_the_same_bytes_as_in_one(monkeypatch, options):
    """Each block's kernels write its own windows, pulses and peaks; a block that took the batch's first window, pulse
    or peak for its own (the peak slots' window index, the CH0 records' phase and noise key) would differ here."""
    model = detection_model("coastal_ocean")
    rng = np.random.default_rng(3)
    n = 300
    ranges = np.where(rng.random(n) < 0.1, np.inf, rng.uniform(1.5, 45.0, n))
    batch = PulseBatch.flat_target(model.instrument, ranges, rng.uniform(0.02, 1.0, n), pulse_id=1000 + np.arange(n))
    monkeypatch.setattr(numba, "get_num_threads", lambda: 1)
    whole = _arrays(simulate(model, batch, seed=8, **options))
    monkeypatch.setattr(blocks, "MIN_BLOCK", 7)
    monkeypatch.setattr(numba, "get_num_threads", lambda: 5)
    cut = _arrays(simulate(model, batch, seed=8, **options))
    assert whole.keys() == cut.keys() and len(whole["ranging.peaks.pulse"]) > n // 2
    for name in whole:
        assert whole[name].dtype == cut[name].dtype and np.array_equal(whole[name], cut[name]), name
