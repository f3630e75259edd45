"""Speed of simulate on this machine."""

from __future__ import annotations

import os
import platform
import time

import numpy as np

from ..optics.optical_model import OpticalModel, PulseBatch
from ..presets import mul2023
from ..ranging.returns import range_batch
from ..receiver.digitiser import digitise
from ..simulate import simulate
from ..water.properties import Water
from .common import (
    _shots,
    _water,
)


def _machine() -> dict:
    import numba

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return {
        "cpu_count": os.cpu_count(), "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": _threading_layer(), "numba_version": numba.__version__,
        "numpy_version": np.__version__, "python": platform.python_version(), "machine": platform.machine(),
        "loadavg_1_5_15": [round(v, 2) for v in load],
    }


def _threading_layer() -> str | None:
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet
        return None


def bench_study(pulses: int = 100_000, full_pulses: int = 10_000, water: str | Water = "coastal_ocean",
                repeats: int = 3, seed: int = 0) -> dict:
    """Pulses per second of :func:`muls.simulate.simulate` (waveform + digitising + ranging).

    Flat 0.1-reflectance targets evenly spread between 2 and 40 m (``np.linspace``), MUL with the pond gate,
    ``pulses`` in windowed mode and ``full_pulses`` in full-record mode, after a warm-up call per mode that
    compiles the kernels. Each mode is timed ``repeats`` times; the reported rate is the median, with the
    digitise / ranging split of that run (``simulate`` is exactly ``digitise`` then ``range_batch``).
    """
    pulses = _shots("pulses", pulses)
    full_pulses = _shots("full_pulses", full_pulses)
    repeats = _shots("repeats", repeats)
    w = _water(water)
    instrument = mul2023()
    model = OpticalModel.build(instrument, w)
    machine_before = _machine()
    for mode in ("windowed", "full"):  # warm-up: compile (or load the cached) kernels
        simulate(model, PulseBatch.flat_target(instrument, np.linspace(2.0, 40.0, 64)), seed, mode=mode)
    result = {}
    for mode, n in (("windowed", pulses), ("full", full_pulses)):
        batch = PulseBatch.flat_target(instrument, np.linspace(2.0, 40.0, n), 0.1)
        runs = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            records = digitise(model, batch, seed, mode=mode)
            t1 = time.perf_counter()
            ranging = range_batch(model, batch, records)
            t2 = time.perf_counter()
            runs.append((t2 - t0, t1 - t0, t2 - t1, int(ranging.returns.pulse.shape[0])))
        runs.sort()
        total, dig_s, rng_s, n_returns = runs[len(runs) // 2]
        result[mode] = {
            "pulses": n, "pulses_per_s": round(n / total, 1), "seconds": round(total, 4),
            "digitise_s": round(dig_s, 4), "range_batch_s": round(rng_s, 4),
            "best_pulses_per_s": round(n / runs[0][0], 1), "all_seconds": [round(r[0], 4) for r in runs],
            "returns": n_returns, "windows": int(records.codes.shape[0]), "samples_per_window": int(records.codes.shape[2]),
        }
    return {
        "windowed_pulses_per_s": result["windowed"]["pulses_per_s"],
        "full_record_pulses_per_s": result["full"]["pulses_per_s"],
        "targets": {"windowed_pulses_per_s": 100_000, "full_record_pulses_per_s": 10_000},
        "windowed": result["windowed"], "full_record": result["full"],
        "machine": {**_machine(), "loadavg_before_1_5_15": machine_before["loadavg_1_5_15"]},
        "settings": {"water": w.name, "instrument": instrument.name, "ranges_m": [2.0, 40.0], "reflectance": 0.1,
                     "repeats": repeats, "seed": int(seed),
                     "record_samples": instrument.digitizer.n_samples, "channels": len(instrument.channels) + 1},
    }
