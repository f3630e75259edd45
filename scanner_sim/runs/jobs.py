"""Many passes into one folder: a :class:`~scanner_sim.runs.tasks.PassJob` per pass, run here or as Dask tasks,
each written into its own sub-folder summary.json last; a pass already complete there for the same inputs is
skipped on a re-run (:func:`completed_summary`).
"""

from __future__ import annotations

import contextlib
import json
import uuid
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
    out = Path(out_dir)
    names = [job.name for job in jobs]
    if len(set(names)) != len(names):
        raise ValueError(f"passes: folder names repeat ({sorted({n for n in names if names.count(n) > 1})})")
    if not checked:
        check_jobs(jobs)
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
            stop_if_signalled()
            bar.set_postfix_str(jobs[k].name)
            outcomes[k] = PassOutcome(jobs[k], "ran", write_pass(out / jobs[k].name, compute_pass(jobs[k])))
            bar.update()
    else:
        from dask.distributed import as_completed

        token = uuid.uuid4().hex[:8]
        futures = {submit_pass(client, jobs[k], retries=retries, token=token): k for k in todo}
        for future in as_completed(futures):
            stop_if_signalled()
            k = futures[future]
            try:
                files = future.result()
                if isinstance(files, Refused):  # a bad input or set-up, tried once
                    outcomes[k] = PassOutcome(jobs[k], "failed", None, files.error)
                else:
                    outcomes[k] = PassOutcome(jobs[k], "ran", write_pass(out / jobs[k].name, files))
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
    with hold_output(out):  # one writer at a time, as run_pass (io/run_dir.py)
        files = compute_pass(job) if client is None else submit_pass(client, job).result()
        if isinstance(files, Refused):
            raise ValueError(files.error)
        return PassResult(write_pass(out, files), out)
