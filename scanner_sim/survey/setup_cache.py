"""The set-up's tables that are the same on every run of a scene and instrument, kept on disk between runs.

A pass's set-up measures its ranging precision through its own physics (:mod:`scanner_sim.survey.ranging_precision`:
16,000 panel shots for cable_survey, 0.3 s on the busy 2-core machine). The table is a pure function of the optical
model (instrument with its gate, water, its Monte Carlo tables, the multiple-scattering rule), the physics' seed,
record mode and channel choice, the panel ranges, and the code; so :func:`cached_ranging_precision` keys it on a
SHA-256 of all of them (the model's parts pickled whole, arrays included, and the size and modification time of
every source file of both packages, :func:`muls.infra.runtime.source_key`) and keeps it in
``$XDG_CACHE_HOME/muls-scanner/tables`` (``~/.cache`` by default), beside the kernel cache
(:func:`muls.infra.runtime.cache_base`). A changed input is another key, so a miss; an entry that does not read
back whole (the zip's CRC, its own key, the shapes) is measured again and replaced, never trusted; a cache that
cannot be written costs the measurement, nothing else. Entries are written atomically.
"""

from __future__ import annotations

import functools
import hashlib
import pickle
import shutil
import time
import zipfile
from pathlib import Path

import numpy as np

from muls.infra.atomic import atomic_open
from muls.infra.runtime import STALE_AFTER_S, cache_base, source_key
from scanner_sim.survey.ranging_precision import RangingPrecision, measure_ranging_precision

#: The packages whose sources every cached table's key includes (the physics and the mission that drives it).
SOURCE_PACKAGES = ("muls", "scanner_sim")


def tables_dir() -> Path:
    """``$XDG_CACHE_HOME/muls-scanner/tables`` (``~/.cache`` by default): the set-up tables of every source state."""
    return cache_base().parent / "tables"


@functools.cache
def code_key() -> str:
    """16 hex digits naming the state of both packages' sources (any edit changes it; read once a process)."""
    import muls
    import scanner_sim

    return source_key(Path(package.__file__).resolve().parent for package in (muls, scanner_sim))


def ranging_key(physics, instrument, ranges_m: tuple[float, ...]) -> str:
    """SHA-256 (hex) of what the ranging-precision table of ``physics`` (:class:`~scanner_sim.survey.setup.Physics`)
    at ``ranges_m`` depends on, code state included."""
    model = physics.model
    content = (instrument, model.instrument, model.water, model.multiple_scattering, model.tables, model.attenuation,
               model.scattering, physics.seed, physics.record_mode, physics.deciding_only, tuple(ranges_m))
    return hashlib.sha256(code_key().encode() + pickle.dumps(content, protocol=5)).hexdigest()


def cached_ranging_precision(physics, instrument, ranges_m: tuple[float, ...]) -> RangingPrecision:
    """:func:`~scanner_sim.survey.ranging_precision.measure_ranging_precision`, read from the cache when an entry of
    the same inputs is there, else measured and stored (module doc)."""
    key = ranging_key(physics, instrument, ranges_m)
    path = tables_dir() / code_key() / f"ranging_{key[:32]}.npz"
    table = _read(path, key)
    if table is None:
        table = measure_ranging_precision(physics, instrument, ranges_m)
        _write(path, key, table)
    return table


def _read(path: Path, key: str) -> RangingPrecision | None:
    """The table stored at ``path`` under ``key``; None when absent, damaged or of another key."""
    try:
        with np.load(path, allow_pickle=False) as entry:
            if str(entry["key"]) != key:
                return None
            table = RangingPrecision(entry["bias_m"], entry["std_m"], entry["count"], entry["snr_edges"],
                                     tuple(float(r) for r in entry["ranges_m"]))
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    shape = table.bias_m.shape
    if not (table.std_m.shape == table.count.shape == shape and len(shape) == 5 and shape[3] == len(table.ranges_m)
            and table.snr_edges.shape == (shape[4] + 1,)):
        return None
    return table


def _write(path: Path, key: str, table: RangingPrecision) -> None:
    """Store ``table`` at ``path`` atomically; an unwritable cache is skipped."""
    try:
        fresh = not path.parent.exists()
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path) as fh:
            np.savez(fh, key=np.array(key), bias_m=table.bias_m, std_m=table.std_m, count=table.count,
                     snr_edges=table.snr_edges, ranges_m=np.asarray(table.ranges_m, float))
    except (OSError, ValueError):
        return
    if fresh:
        _remove_stale(path.parent)


def _remove_stale(current: Path) -> None:
    """Remove the tables of other source states left untouched for :data:`~muls.infra.runtime.STALE_AFTER_S`."""
    now = time.time()
    for folder in current.parent.iterdir():
        try:
            if folder != current and folder.is_dir() and now - folder.stat().st_mtime > STALE_AFTER_S:
                shutil.rmtree(folder, ignore_errors=True)
        except OSError:
            continue

