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

import tempfile
import time
import uuid
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

from muls.infra.runtime import configure_process
from scanner_sim.config import SceneConfig
from scanner_sim.survey.chunk import Chunk
from scanner_sim.survey.pipeline import kept_slots, pass_chunk, run_pass, stream_to_files
from scanner_sim.survey.setup import PassOptions, PassSetup

#: Times a task that raised is tried again (a task whose worker died is rescheduled by the scheduler
#: itself, up to ``distributed.scheduler.allowed-failures`` times).
DEFAULT_RETRIES = 2

@dataclass(frozen=True)
class PassJob:
    """One pass to run: its folder name, its scene (every override applied), its options, and the number of
    segments its pulse slots are cut into (1: one task)."""

    name: str
    config: SceneConfig
    options: PassOptions = PassOptions()
    segments: int = 1


class PassFiles(NamedTuple):
    """A pass's output files by their path in its folder, bytes and all (summary.json among them)."""

    files: dict[str, bytes]


class Segment(NamedTuple):
    """The chunks of one segment of a pass, in slot order (their ``waveforms`` dropped), and the seconds they took."""

    chunks: list[Chunk]
    wall_s: float


def _read_files(folder: Path) -> PassFiles:
    """Every file of the pass's folder, by its path in the folder (``rosbag/metadata.yaml`` for a bag's)."""
    return PassFiles({p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
                      if p.is_file()})


def pass_files(config: SceneConfig, options: PassOptions) -> PassFiles:
    """Task: one whole pass with :func:`run_pass`, in a private temporary folder; returns its files."""
    configure_process()
    with tempfile.TemporaryDirectory(prefix="muls-pass-") as tmp:
        run_pass(config, tmp, replace(options, progress=False))
        return _read_files(Path(tmp))


def segment_chunks(setup: PassSetup, index: int, count: int) -> list:
    """Slots (n,) int64 of segment ``index`` of ``count``: a contiguous run of the pass's chunks."""
    chunks = list(setup.slot_chunks())
    n = len(chunks)
    return chunks[index * n // count:(index + 1) * n // count]


def simulate_segment(config: SceneConfig, options: PassOptions, index: int, count: int) -> Segment:
    """Task: segment ``index`` of ``count`` of the pass, simulated chunk by chunk."""
    configure_process()
    setup = PassSetup.build(config, options)
    started = time.perf_counter()
    keep = kept_slots(setup, options.waveforms, setup.config.output.waveform_every_n_pulses)
    chunks = [pass_chunk(setup, slots, keep)._replace(waveforms=None) for slots in segment_chunks(setup, index, count)]
    return Segment(chunks, time.perf_counter() - started)


def merge_segments(config: SceneConfig, options: PassOptions, *segments: Segment) -> PassFiles:
    """Task: the segments, in order, through the sinks of :func:`run_pass` (same order, same files).

    The summary's ``wall_s`` is the segments' and the merge's seconds added up (the pass's work, wherever it
    ran), so ``pulses_per_s`` stays the throughput of one worker.
    """
    configure_process()
    t_setup = time.perf_counter()
    setup = PassSetup.build(config, options)
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


class Refused(NamedTuple):
    """What a task returns instead of raising a ValueError (a bad input or set-up: the same on any worker, so
    Dask must not retry it): the error in one line."""

    error: str


def on_worker(task, *args):
    """Run ``task(*args)`` as a Dask task: with one numba thread, since the workers (one thread each) are
    the parallelism; numba's own threads on top would oversubscribe the cores (measured: a third more CPU
    time for the same coverage sweep on 2 cores). A ValueError is returned as :class:`Refused`, not raised, so
    it is tried once and logged by no worker; a refused segment's merge is refused with it."""
    import numba

    refused = next((arg for arg in args if isinstance(arg, Refused)), None)
    if refused is not None:
        return refused
    numba.set_num_threads(1)
    try:
        return task(*args)
    except ValueError as exc:
        return Refused(" ".join(f"{type(exc).__name__}: {exc}".split()))


def submit_pass(client, job: PassJob, *, retries: int = DEFAULT_RETRIES, token: str | None = None):
    """Submit ``job`` to ``client``; returns the future of its :class:`PassFiles` (a merge of segment
    futures when ``job.segments`` > 1), or of a :class:`Refused`. Keys read ``pass-NAME-TOKEN`` on the dashboard."""
    token = token or uuid.uuid4().hex[:8]
    key = f"pass-{job.name}-{token}"
    if job.segments == 1:
        return client.submit(on_worker, pass_files, job.config, job.options, key=key, retries=retries, pure=False)
    parts = [client.submit(on_worker, simulate_segment, job.config, job.options, i, job.segments,
                           key=f"segment-{i}-{key}", retries=retries, pure=False) for i in range(job.segments)]
    return client.submit(on_worker, merge_segments, job.config, job.options, *parts, key=key, retries=retries,
                         pure=False)
