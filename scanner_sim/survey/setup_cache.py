"""What a pass's set-up builds the same on every run of a scene and instrument, kept on disk between runs: the
ranging-precision table and the built scene.

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

The built scene (:func:`~scanner_sim.world.scene.build_scene`: the seabed's height field and mesh, the objects'
meshes, the cable's spline, the faces' normals and smooth surfaces; 1.0 to 1.3 s for cable_survey's 352,488
triangles, 0.04 s to read back) is kept the same way by :func:`stored_scene` in ``.../muls-scanner/scenes``, keyed
on the scene sections it is built from (seabed, objects, CRS; a raster's window follows the survey's plan), the
path, size and modification time of the raster and mesh files they read, and the code. An entry is the scene
pickled whole under its key and the SHA-256 of the pickle, read back only when both match (so never a damaged
one); the cache is this user's own, as numba's pickled kernels beside it. The least recently used scenes, of any
source state, go beyond :data:`SCENES_KEPT_BYTES`. Within one process :func:`cached_scene` hands the passes of one
scene in a row (a campaign's, a study's) the same scene object, read once, over which the ray stage builds its BVH
once (:meth:`~scanner_sim.rays.cast.CastScene.of`): the example campaign's four passes of cable_survey took 3.2 s
instead of 4.2.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import pickle
import shutil
import time
import zipfile
from pathlib import Path

import numpy as np

from muls.infra.atomic import atomic_open
from muls.infra.runtime import STALE_AFTER_S, cache_base, source_key
from scanner_sim.config.geometry import MeshObject
from scanner_sim.config.raster_seabed import RasterSeabedConfig
from scanner_sim.survey.provenance import raster_files
from scanner_sim.survey.ranging_precision import RangingPrecision, measure_ranging_precision
from scanner_sim.world.raster import plan_bounds
from scanner_sim.world.scene import Scene, build_scene
from scanner_sim.world.site import SiteScene

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


#: Bytes of built scenes kept, all source states together (the least recently used go beyond it): a campaign
#: sweeping a seabed key writes one scene per value, and each edit of the code a scene per scene run, some 30 MB for
#: cable_survey's.
SCENES_KEPT_BYTES = 1 << 30


def scenes_dir() -> Path:
    """``$XDG_CACHE_HOME/muls-scanner/scenes`` (``~/.cache`` by default): the built scenes of every source state."""
    return cache_base().parent / "scenes"


def scene_key(config) -> str:
    """SHA-256 (hex) of what :func:`~scanner_sim.world.scene.build_scene` builds ``config``'s scene from: its seabed,
    objects and CRS sections as validated (a grid or mesh given in memory by its digest), the survey's plan bounds
    for a raster seabed (the window it reads), the path, size and modification time of every raster and mesh file,
    and the code state."""
    files = [*raster_files(config), *(o.resolved_path for o in config.objects
                                      if isinstance(o, MeshObject) and o.resolved_path is not None)]
    content = {
        "sections": config.model_dump(mode="json", include={"seabed", "objects", "crs"}),
        "plan_bounds": plan_bounds(config) if isinstance(config.seabed, RasterSeabedConfig) else None,
        "files": [_file_stamp(path) for path in files],
    }
    text = json.dumps(content, sort_keys=True, ensure_ascii=True)
    return hashlib.sha256(code_key().encode() + text.encode()).hexdigest()


#: The scene this process built or read last, by its key: passes of one scene in a row (a campaign's, a study's, a
#: segmented pass's) share one scene object, and with it the BVH built over it
#: (:meth:`~scanner_sim.rays.cast.CastScene.of`). One is kept, and never a site's (:class:`SiteScene`: gigabytes, its
#: windows built pass by pass), so what stays in memory after a pass is at most one scene of the usual size.
_LAST_SCENE: dict[str, Scene] = {}


def cached_scene(config) -> Scene | SiteScene:
    """``build_scene(config)``: this process's last scene when it has the same key, else :func:`stored_scene`."""
    key = scene_key(config)
    scene = _LAST_SCENE.get(key)
    if scene is None:
        scene = stored_scene(config, key)
        _LAST_SCENE.clear()
        if not isinstance(scene, SiteScene):
            _LAST_SCENE[key] = scene
    return scene


def stored_scene(config, key: str | None = None) -> Scene | SiteScene:
    """``build_scene(config)``, read from the cache on disk when an entry of the same inputs is there, else built and
    stored (module doc); ``key``: :func:`scene_key` of ``config``, when the caller has it."""
    key = key or scene_key(config)
    path = scenes_dir() / code_key() / f"scene_{key[:32]}.pickle"
    scene = _read_scene(path, key)
    if scene is None:
        scene = build_scene(config)
        _write_scene(path, key, scene)
    return scene


def _file_stamp(path: Path) -> list:
    stat = Path(path).stat()
    return [str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns]


#: Bytes of an entry's key (hex) and of the SHA-256 of its pickle, before the pickle.
_KEY_BYTES, _DIGEST_BYTES = 64, 32


def _read_scene(path: Path, key: str) -> Scene | SiteScene | None:
    """The scene stored at ``path`` under ``key``; None when absent, of another key or damaged (its digest)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    head, digest, payload = data[:_KEY_BYTES], data[_KEY_BYTES:_KEY_BYTES + _DIGEST_BYTES], data[_KEY_BYTES + _DIGEST_BYTES:]
    if head != key.encode() or hashlib.sha256(payload).digest() != digest:
        return None
    try:
        scene = pickle.loads(payload)
    except Exception:  # the digest matched, so only code that no longer reads it (the key holds the code state)
        return None
    if not isinstance(scene, (Scene, SiteScene)):
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # recently used: kept before older entries (_trim)
    return scene


def _write_scene(path: Path, key: str, scene: Scene | SiteScene) -> None:
    """Store ``scene`` at ``path`` atomically; an unwritable cache (or a scene holding what pickle cannot store) is
    skipped: the next run builds it again."""
    try:
        payload = pickle.dumps(scene, protocol=pickle.HIGHEST_PROTOCOL)
        fresh = not path.parent.exists()
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path) as fh:
            fh.write(key.encode() + hashlib.sha256(payload).digest())
            fh.write(payload)
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        return
    if fresh:
        _remove_stale(path.parent)
    _trim(scenes_dir(), SCENES_KEPT_BYTES, keep=path)


def _trim(folder: Path, budget: int, keep: Path) -> None:
    """Remove the least recently used scenes under ``folder`` (of every source state; but ``keep``) until the rest
    hold at most ``budget`` bytes."""
    entries = []
    for entry in folder.glob("*/scene_*.pickle"):
        with contextlib.suppress(OSError):
            stat = entry.stat()
            entries.append((stat.st_mtime_ns, stat.st_size, entry))
    total = sum(size for _, size, _ in entries)
    for _, size, entry in sorted(entries, key=lambda e: e[:2]):
        if total <= budget:
            return
        if entry != keep:
            with contextlib.suppress(OSError):
                entry.unlink()
                total -= size


def _remove_stale(current: Path) -> None:
    """Remove the entries of other source states left untouched for :data:`~muls.infra.runtime.STALE_AFTER_S`."""
    now = time.time()
    for folder in current.parent.iterdir():
        try:
            if folder != current and folder.is_dir() and now - folder.stat().st_mtime > STALE_AFTER_S:
                shutil.rmtree(folder, ignore_errors=True)
        except OSError:
            continue

