"""Many passes into one folder: a :class:`~scanner_sim.runs.tasks.PassJob` per pass, run here or as Dask tasks,
each written into its own sub-folder summary.json last; a pass already complete there for the same inputs is
skipped on a re-run (:func:`completed_summary`).
"""

from __future__ import annotations

import contextlib
import json
import uuid
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from muls.infra.signals import stop_if_signalled
from scanner_sim import io
from scanner_sim.config import ConfigError, SceneConfig
from scanner_sim.io.run_dir import hold_output
from scanner_sim.runs.tasks import (
    DEFAULT_RETRIES,
    PassFiles,
    PassJob,
    Refused,
    compute_pass,
    submit_pass,
)
from scanner_sim.survey.pipeline import PassResult
from scanner_sim.survey.provenance import inputs_fingerprint
from scanner_sim.survey.setup import PassOptions, PassPlan, checked_trajectory
from scanner_sim.survey.setup_cache import cached_scene

#: Keys of summary.json that time the pass: they differ from run to run.
TIMING_KEYS = ("wall_s", "setup_s", "compile_s", "pulses_per_s")



@dataclass(frozen=True)
class PassOutcome:
    """What became of a job: ``status`` is ``ran``, ``skipped`` (complete from an earlier run) or ``failed``;
    ``summary`` as written to summary.json (None when failed), ``error`` the failure in one line."""

    job: PassJob
    status: str
    summary: dict | None
    error: str | None = None


def write_pass(folder: Path, files: PassFiles) -> dict:
    """Write a pass's files into ``folder`` (each atomically), summary.json last; returns the summary.

    An earlier summary.json is removed first, so until this pass is wholly written the folder does not
    look complete."""
    folder.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        (folder / "summary.json").unlink()
    for name, data in sorted(files.files.items(), key=lambda item: item[0] == "summary.json"):
        (folder / name).parent.mkdir(parents=True, exist_ok=True)  # a file in a sub-folder: a bag's
        with io.atomic_path(folder / name) as tmp:
            tmp.write_bytes(data)
    return json.loads(files.files["summary.json"])


def job_fingerprint(job: PassJob) -> str:
    """The inputs fingerprint (:func:`~scanner_sim.survey.provenance.inputs_fingerprint`) of the pass ``job`` would
    write: of its whole scene (every sweep value and option applied), mesh files, resolved water and instrument,
    fidelity level, output options and the output format's version."""
    config = job.config.with_overrides(job.options.scene_overrides())
    return inputs_fingerprint(config, job.options, PassPlan.of(config, job.options).level)


def completed_summary(folder: Path, job: PassJob) -> dict | None:
    """The summary of ``job``'s pass if ``folder`` holds it complete, else None.

    Complete: summary.json (written last, after every other file) parses, its ``provenance.inputs_fingerprint``
    is ``job``'s (:func:`job_fingerprint`: a changed scene value, water, instrument, option or output format makes
    another), and every file of the pass's plan (:class:`~scanner_sim.survey.setup.PassPlan`) is there (a pass run
    before without renders is run again with them)."""
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    provenance = summary.get("provenance") if isinstance(summary, dict) else None
    if not isinstance(provenance, dict) or provenance.get("inputs_fingerprint") != job_fingerprint(job):
        return None
    if not all((folder / name).is_file() for name in PassPlan.of(job.config, job.options).files):
        return None
    return summary


def check_jobs(jobs: Sequence[PassJob], passes: int | None = None) -> None:
    """Run every job's set-up checks here, before any pass runs: the pass's size and memory, its start within the
    track (:func:`~scanner_sim.survey.sizing.check_pass_budget`), and its built track against the water surface, the
    seabed and the objects (:func:`~scanner_sim.survey.setup.checked_trajectory`). Raises the first refusal as a
    ConfigError naming the pass; a set-up error is then never met in a task, where it would be retried and
    reported only when its pass started. Passes that would all write one bag folder (``output.rosbag.dir``) are
    refused: each would replace the one before. ``passes``: how many passes write into one folder, when ``jobs`` are
    some of them (a dataset checks its scenes as it draws them); default ``len(jobs)``."""
    passes = len(jobs) if passes is None else passes
    for job in jobs:
        config = job.config.with_overrides(job.options.scene_overrides())
        bag = config.output.rosbag
        if passes > 1 and bag is not None and bag.dir is not None:
            raise ConfigError(f"output.rosbag.dir = {bag.dir!r}: the {passes:,} passes would each replace the one "
                              "bag there; leave dir out, so that each pass writes rosbag/ in its own folder")
        try:
            checked_trajectory(config, cached_scene(job.config))
        except ConfigError as exc:
            raise ConfigError(f"pass {job.name}: {exc}") from None


def run_jobs(jobs: Sequence[PassJob], out_dir: str | Path, client=None, *, retries: int = DEFAULT_RETRIES,
             redo: bool = False, progress: bool = True, checked: bool = False) -> list[PassOutcome]:
    """Run ``jobs`` into ``out_dir/JOB.name/`` and return their outcomes in the order of ``jobs``; their set-ups are
    checked first (:func:`check_jobs`) unless the caller did (``checked``).

    Passes already complete there are skipped (unless ``redo``). With a Dask ``client``, every other pass
    is submitted at once and written as it finishes; a pass whose task fails (after ``retries``) is
    reported failed and the others go on. Without one, they run here one after another, and an error
    propagates.
    """
    names = [job.name for job in jobs]
    if len(set(names)) != len(names):
        raise ValueError(f"passes: folder names repeat ({sorted({n for n in names if names.count(n) > 1})})")
    if not checked:
        check_jobs(jobs)
    queue = PassQueue(out_dir, client, retries=retries, redo=redo, progress=progress, checked=True)
    for k, job in enumerate(jobs):
        queue.put(job, k)
    outcomes = dict(queue.finished())
    queue.close()
    return [outcomes[k] for k in range(len(jobs))]


class PassQueue:
    """Passes handed in over time (:meth:`put`) and taken back as each finishes (:meth:`next_finished`), written into
    ``out_dir/JOB.name/`` as :func:`run_jobs` writes them. With a Dask ``client`` a pass runs as a task from the moment
    it is put, so that a caller can hand in the next pass of one chain of passes while those of the others still run
    (a plan's confirmations: docs/planning.md); a pass whose task fails (after ``retries``) comes back failed. Without
    one, a pass runs here when it is taken, the earliest put first, and an error propagates. A pass complete in its
    folder already comes back ``skipped`` (unless ``redo``). Each pass's set-up is checked as it is put
    (:func:`check_jobs`, as one of several passes into the folder) unless the caller did (``checked``)."""

    def __init__(self, out_dir: str | Path, client=None, *, retries: int = DEFAULT_RETRIES, redo: bool = False,
                 progress: bool = True, checked: bool = False):
        self.out, self.client, self.retries, self.redo, self.checked = Path(out_dir), client, retries, redo, checked
        self._token = uuid.uuid4().hex[:8]
        self._names: set[str] = set()
        self._skipped: deque = deque()  # (key, outcome) of passes complete already
        self._here: deque = deque()  # (key, job) to run in this process, without a client
        self._tasks: dict = {}  # future -> (key, job)
        self._finishing = None  # dask's as_completed over the tasks, from the first submitted
        self._bar = tqdm(total=0, unit="pass", disable=not progress, desc="passes")

    def put(self, job: PassJob, key=None) -> None:
        """Hand in ``job``; :meth:`next_finished` gives it back with ``key`` (default its name)."""
        if job.name in self._names:
            raise ValueError(f"passes: folder names repeat ({job.name!r})")
        if not self.checked:
            check_jobs([job], passes=2)
        self._names.add(job.name)
        key = job.name if key is None else key
        self._bar.total += 1
        self._bar.refresh()
        summary = None if self.redo else completed_summary(self.out / job.name, job)
        if summary is not None:
            self._skipped.append((key, PassOutcome(job, "skipped", summary)))
        elif self.client is None:
            self._here.append((key, job))
        else:
            from dask.distributed import as_completed

            future = submit_pass(self.client, job, retries=self.retries, token=self._token)
            self._tasks[future] = (key, job)
            if self._finishing is None:
                self._finishing = as_completed([future])
            else:
                self._finishing.add(future)

    def pending(self) -> int:
        """Passes put and not yet taken back."""
        return len(self._skipped) + len(self._here) + len(self._tasks)

    def next_finished(self) -> tuple:
        """(key, :class:`PassOutcome`) of the next pass to finish (a skipped one at once); waits for it. IndexError
        when none is pending."""
        if self._skipped:
            return self._taken(*self._skipped.popleft())
        stop_if_signalled()
        if self._here:
            key, job = self._here.popleft()
            self._bar.set_postfix_str(job.name)
            return self._taken(key, PassOutcome(job, "ran", write_pass(self.out / job.name, compute_pass(job))))
        if not self._tasks:
            raise IndexError("next_finished: no pass is pending")
        future = next(self._finishing)
        stop_if_signalled()
        key, job = self._tasks.pop(future)
        try:
            files = future.result()
            if isinstance(files, Refused):  # a bad input or set-up, tried once
                outcome = PassOutcome(job, "failed", None, files.error)
            else:
                outcome = PassOutcome(job, "ran", write_pass(self.out / job.name, files))
        except Exception as exc:  # the task's own error, after its retries; the others go on
            outcome = PassOutcome(job, "failed", None, f"{type(exc).__name__}: {exc}".splitlines()[0])
        future.release()
        self._bar.set_postfix_str(job.name)
        return self._taken(key, outcome)

    def finished(self):
        """(key, outcome) of every pending pass, as each finishes."""
        while self.pending():
            yield self.next_finished()

    def close(self) -> None:
        """Close the progress bar."""
        self._bar.close()

    def _taken(self, key, outcome: PassOutcome) -> tuple:
        self._bar.update()
        return key, outcome


def run_pass_segmented(config: SceneConfig, out_dir: str | Path, options: PassOptions = PassOptions(),
                       segments: int = 4, client=None) -> PassResult:
    """One pass cut into ``segments`` runs of pulse slots, simulated as separate tasks on ``client`` (in this
    process without one) and merged in order into ``out_dir``: points.las, dropouts.npz and the other files
    are byte-identical to :func:`run_pass`'s, summary.json too but for its timings (:data:`TIMING_KEYS`)."""
    if not (isinstance(segments, int) and segments >= 1):
        raise ValueError(f"segments = {segments!r}: must be an integer >= 1")
    out = Path(out_dir or config.output_dir)
    job = PassJob(out.name, config, options, segments)
    with hold_output(out):  # one writer at a time, as run_pass (io/run_dir.py)
        files = compute_pass(job) if client is None else submit_pass(client, job).result()
        if isinstance(files, Refused):
            raise ValueError(files.error)
        return PassResult(write_pass(out, files), out)
