"""Survey passes as Dask tasks: many passes side by side, or one long pass cut in time, on the workers of a
``dask.distributed`` cluster (a ``LocalCluster`` on this machine, or any scheduler), bit-identical to the
serial :func:`~scanner_sim.survey.pipeline.run_pass` (docs/campaigns.md).

The flow of one pass: :func:`compute_pass` (a task, or in this process) returns the pass's files as bytes,
and :func:`write_pass` puts them in the pass's folder, summary.json last. A task never writes into the
output folder itself: it runs in a private temporary folder. So a task can run again anywhere after a
worker dies, a pass cut short leaves no summary.json (the proof of a complete pass), and workers need no
file system shared with the client.

A pass cut into K segments: K tasks of :func:`simulate_segment` each build the pass's set-up and simulate
one contiguous run of its chunks (the chunks of :meth:`PassSetup.slot_chunks`); :func:`merge_segments`
feeds them, in order, through the same sinks as ``run_pass``. Every random draw is keyed by the pulse slot,
so the chunks, and hence the files, are the serial pass's.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

from tqdm import tqdm

from scanner_sim import io
from scanner_sim.config import SceneConfig
from scanner_sim.rays.cast import tune_memory
from scanner_sim.survey.pipeline import Chunk, PassOptions, PassResult, PassSetup, run_pass, stream_to_files
from scanner_sim.world.scene import Scene, build_scene

#: Times a task that raised is tried again (a task whose worker died is rescheduled by the scheduler
#: itself, up to ``distributed.scheduler.allowed-failures`` times).
DEFAULT_RETRIES = 2
#: Dask settings of the local cluster's workers. The statistical profiler samples the task's stack every
#: 10 ms from the worker's event loop, competing with the pass for the GIL: measured on 2 cores, 4 passes
#: of 100,000 pulses on 2 workers took 26-30 s of CPU without it, 36 s with it (19 s in one process).
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}
#: Keys of summary.json that time the pass: they differ from run to run.
TIMING_KEYS = ("wall_s", "setup_s", "pulses_per_s")


@dataclass(frozen=True)
class PassJob:
    """One pass to run: its folder name, its scene (every override applied), its options, and the number of
    segments its pulse slots are cut into (1: one task)."""

    name: str
    config: SceneConfig
    options: PassOptions = PassOptions()
    segments: int = 1


class PassFiles(NamedTuple):
    """A pass's output files by name, bytes and all (summary.json among them)."""

    files: dict[str, bytes]


class Segment(NamedTuple):
    """The chunks of one segment of a pass, in slot order (``records`` dropped), and the seconds they took."""

    chunks: list[Chunk]
    wall_s: float


@dataclass(frozen=True)
class PassOutcome:
    """What became of a job: ``status`` is ``ran``, ``skipped`` (complete from an earlier run) or ``failed``;
    ``summary`` as written to summary.json (None when failed), ``error`` the failure in one line."""

    job: PassJob
    status: str
    summary: dict | None
    error: str | None = None


# -- tasks ----------------------------------------------------------------------------------------------
_SCENES: dict[str, Scene] = {}


def cached_scene(config: SceneConfig) -> Scene:
    """The built scene of ``config``, kept per process: the scene depends only on the seabed and the
    objects (and the folder mesh files are found in), so passes that differ in water, instrument, platform,
    scanner or survey share one build. One scene is kept."""
    key = config.model_dump_json(include={"seabed", "objects"}) + str(config.source_path)
    if key not in _SCENES:
        _SCENES.clear()
        _SCENES[key] = build_scene(config)
    return _SCENES[key]


def _read_files(folder: Path) -> PassFiles:
    return PassFiles({p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()})


def pass_files(config: SceneConfig, options: PassOptions) -> PassFiles:
    """Task: one whole pass with :func:`run_pass`, in a private temporary folder; returns its files."""
    tune_memory()
    with tempfile.TemporaryDirectory(prefix="muls-pass-") as tmp:
        run_pass(config, tmp, replace(options, progress=False), scene=cached_scene(config))
        return _read_files(Path(tmp))


def segment_chunks(setup: PassSetup, index: int, count: int) -> list:
    """Slots (n,) int64 of segment ``index`` of ``count``: a contiguous run of the pass's chunks."""
    chunks = list(setup.slot_chunks())
    n = len(chunks)
    return chunks[index * n // count:(index + 1) * n // count]


def simulate_segment(config: SceneConfig, options: PassOptions, index: int, count: int) -> Segment:
    """Task: segment ``index`` of ``count`` of the pass, simulated chunk by chunk."""
    tune_memory()
    setup = PassSetup.build(config, options, cached_scene(config))
    started = time.perf_counter()
    footprint = setup.scene.heightfield is not None  # coverage needs the nominal footprint, as in run_pass
    chunks = [setup.simulate_chunk(slots, footprint=footprint)._replace(records=None)
              for slots in segment_chunks(setup, index, count)]
    return Segment(chunks, time.perf_counter() - started)


def merge_segments(config: SceneConfig, options: PassOptions, *segments: Segment) -> PassFiles:
    """Task: the segments, in order, through the sinks of :func:`run_pass` (same order, same files).

    The summary's ``wall_s`` is the segments' and the merge's seconds added up (the pass's work, wherever it
    ran), so ``pulses_per_s`` stays the throughput of one worker.
    """
    tune_memory()
    t_setup = time.perf_counter()
    setup = PassSetup.build(config, options, cached_scene(config))
    setup_s = time.perf_counter() - t_setup
    chunks = [chunk for segment in segments for chunk in segment.chunks]
    expected = [slots.size for slots in setup.slot_chunks()]
    if [chunk.slots.size for chunk in chunks] != expected:
        raise RuntimeError(f"merge_segments: the segments hold {len(chunks)} chunks, the pass has {len(expected)}")
    with tempfile.TemporaryDirectory(prefix="muls-pass-") as tmp:
        out = Path(tmp)
        stream_to_files(setup, out, chunks, options, setup_s, sum(segment.wall_s for segment in segments))
        return _read_files(out)


def compute_pass(job: PassJob) -> PassFiles:
    """The files of ``job``, computed in this process by the same functions the tasks run."""
    if job.segments == 1:
        return pass_files(job.config, job.options)
    return merge_segments(job.config, job.options,
                          *(simulate_segment(job.config, job.options, i, job.segments) for i in range(job.segments)))


def on_worker(task, *args):
    """Run ``task(*args)`` as a Dask task: with one numba thread, since the workers (one thread each) are
    the parallelism; numba's own threads on top would oversubscribe the cores (measured: a third more CPU
    time for the same coverage sweep on 2 cores)."""
    import numba

    numba.set_num_threads(1)
    return task(*args)


def submit_pass(client, job: PassJob, *, retries: int = DEFAULT_RETRIES, token: str | None = None):
    """Submit ``job`` to ``client``; returns the future of its :class:`PassFiles` (a merge of segment
    futures when ``job.segments`` > 1). Keys read ``pass-NAME-TOKEN`` on the dashboard."""
    token = token or uuid.uuid4().hex[:8]
    key = f"pass-{job.name}-{token}"
    if job.segments == 1:
        return client.submit(on_worker, pass_files, job.config, job.options, key=key, retries=retries, pure=False)
    parts = [client.submit(on_worker, simulate_segment, job.config, job.options, i, job.segments,
                           key=f"segment-{i}-{key}", retries=retries, pure=False) for i in range(job.segments)]
    return client.submit(on_worker, merge_segments, job.config, job.options, *parts, key=key, retries=retries,
                         pure=False)


# -- the output folder ----------------------------------------------------------------------------------
def write_pass(folder: Path, files: PassFiles) -> dict:
    """Write a pass's files into ``folder`` (each atomically), summary.json last; returns the summary.

    An earlier summary.json is removed first, so until this pass is wholly written the folder does not
    look complete."""
    folder.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        (folder / "summary.json").unlink()
    for name, data in sorted(files.files.items(), key=lambda item: item[0] == "summary.json"):
        with io.atomic_path(folder / name) as tmp:
            tmp.write_bytes(data)
    return json.loads(files.files["summary.json"])


def expected_files(job: PassJob) -> list[str]:
    """Files a complete pass of ``job`` has besides summary.json, those the options (not the run) decide:
    dropouts.npz always, render.png when rendering a point cloud."""
    output = job.config.output
    return ["dropouts.npz"] + (["render.png"] if job.options.render and (output.las or output.laz) else [])


def fingerprint(summary: dict) -> dict:
    """What a summary says about the inputs of its pass: scene, water, seed, fidelity, instrument, pulses
    and coverage settings."""
    settings, coverage = summary.get("settings") or {}, summary.get("coverage") or {}
    return {"scene": summary.get("scene"), "water": summary.get("water"), "seed": summary.get("seed"),
            "fidelity": summary.get("fidelity"), "instrument": settings.get("instrument"),
            "max_pulses": settings.get("max_pulses"),
            **{key: coverage.get(key) for key in ("cell_m", "min_points", "tolerance_m")}}


def job_fingerprint(job: PassJob) -> dict:
    """:func:`fingerprint` of the summary ``job`` would write."""
    config = job.config.with_overrides(job.options.scene_overrides())
    settings = job.options.coverage
    coverage = ({"cell_m": settings.cell_m, "min_points": settings.min_points, "tolerance_m": settings.tolerance_m}
                if config.seabed is not None else dict.fromkeys(("cell_m", "min_points", "tolerance_m")))
    return {"scene": config.name, "water": config.water.preset or config.water_model().name,
            "seed": config.survey.seed, "fidelity": config.survey.level.name,
            "instrument": config.instrument_model().name, "max_pulses": config.survey.max_pulses, **coverage}


def completed_summary(folder: Path, job: PassJob) -> dict | None:
    """The summary of ``job``'s pass if ``folder`` holds it complete, else None.

    Complete: summary.json (written last, after every other file) parses and names the same scene, water,
    seed, fidelity, instrument, pulse limit and coverage settings, and the files of :func:`expected_files`
    are there (a pass run before without renders is run again with them)."""
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(summary, dict) or fingerprint(summary) != job_fingerprint(job):
        return None
    if not all((folder / name).is_file() for name in expected_files(job)):
        return None
    return summary


# -- running many -----------------------------------------------------------------------------------------
def run_jobs(jobs: Sequence[PassJob], out_dir: str | Path, client=None, *, retries: int = DEFAULT_RETRIES,
             redo: bool = False, progress: bool = True) -> list[PassOutcome]:
    """Run ``jobs`` into ``out_dir/JOB.name/`` and return their outcomes in the order of ``jobs``.

    Passes already complete there are skipped (unless ``redo``). With a Dask ``client``, every other pass
    is submitted at once and written as it finishes; a pass whose task fails (after ``retries``) is
    reported failed and the others go on. Without one, they run here one after another, and an error
    propagates.
    """
    out = Path(out_dir)
    names = [job.name for job in jobs]
    if len(set(names)) != len(names):
        raise ValueError(f"passes: folder names repeat ({sorted({n for n in names if names.count(n) > 1})})")
    outcomes: dict[int, PassOutcome] = {}
    todo = []
    for k, job in enumerate(jobs):
        summary = None if redo else completed_summary(out / job.name, job)
        if summary is not None:
            outcomes[k] = PassOutcome(job, "skipped", summary)
        else:
            todo.append(k)
    bar = tqdm(total=len(jobs), initial=len(jobs) - len(todo), unit="pass", disable=not progress, desc="passes")
    if client is None:
        for k in todo:
            bar.set_postfix_str(jobs[k].name)
            outcomes[k] = PassOutcome(jobs[k], "ran", write_pass(out / jobs[k].name, compute_pass(jobs[k])))
            bar.update()
    else:
        from dask.distributed import as_completed

        token = uuid.uuid4().hex[:8]
        futures = {submit_pass(client, jobs[k], retries=retries, token=token): k for k in todo}
        for future in as_completed(futures):
            k = futures[future]
            try:
                outcomes[k] = PassOutcome(jobs[k], "ran", write_pass(out / jobs[k].name, future.result()))
            except Exception as exc:  # the task's own error, after its retries; the others go on
                outcomes[k] = PassOutcome(jobs[k], "failed", None, f"{type(exc).__name__}: {exc}".splitlines()[0])
            future.release()
            bar.set_postfix_str(jobs[k].name)
            bar.update()
    bar.close()
    return [outcomes[k] for k in range(len(jobs))]


def run_pass_segmented(config: SceneConfig, out_dir: str | Path, options: PassOptions = PassOptions(),
                       segments: int = 4, client=None) -> PassResult:
    """One pass cut into ``segments`` runs of pulse slots, simulated as separate tasks on ``client`` (in this
    process without one) and merged in order into ``out_dir``: points.las, dropouts.npz and the other files
    are byte-identical to :func:`run_pass`'s, summary.json too but for its timings (:data:`TIMING_KEYS`)."""
    if not (isinstance(segments, int) and segments >= 1):
        raise ValueError(f"segments = {segments!r}: must be an integer >= 1")
    out = Path(out_dir or config.output_dir)
    job = PassJob(out.name, config, options, segments)
    files = compute_pass(job) if client is None else submit_pass(client, job).result()
    return PassResult(write_pass(out, files), out)


# -- clusters ---------------------------------------------------------------------------------------------
def default_workers() -> int:
    """Workers of a local cluster by default: one per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, *,
                dashboard: bool = True) -> Iterator:
    """A ``dask.distributed.Client``: of the scheduler at ``scheduler`` (``tcp://host:8786``), or of a new
    ``LocalCluster`` on this machine's loopback with ``workers`` worker processes (default: one per core)
    of one thread each, its dashboard on loopback (a free port) unless ``dashboard`` is False."""
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    n = default_workers() if workers is None else workers
    if not (isinstance(n, int) and n >= 1):
        raise ValueError(f"workers = {workers!r}: must be an integer >= 1")
    with dask.config.set(WORKER_CONFIG):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0" if dashboard else None)
    with cluster, Client(cluster) as client:
        yield client


@contextlib.contextmanager
def maybe_client(client=None, scheduler: str | None = None, workers: int | None = None,
                 dashboard: bool = True, announce: bool = False) -> Iterator:
    """``client`` if given; else a client of ``scheduler``, or of a local cluster of ``workers`` (> 0);
    else None (``workers`` 0 or None: run in this process). ``announce`` prints the dashboard address."""
    if client is not None or (not scheduler and not workers):
        yield client
        return
    if not scheduler and not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"workers = {workers!r}: must be an integer >= 0 (0: in this process, without Dask)")
    with dask_client(scheduler, workers, dashboard=dashboard) as new:
        if announce:
            where = scheduler or f"a local cluster of {len(new.scheduler_info()['workers'])} workers"
            print(f"Dask: {where}; dashboard {new.dashboard_link}", flush=True)
        yield new
