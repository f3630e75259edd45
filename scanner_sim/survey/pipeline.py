"""A survey pass end to end: chunks of pulses flow through poses, mirror directions, beam sub-rays, hits and
the receiver check, the MULS waveforms and ranging, then georeferencing, and on to the sinks (LAS, dropouts,
coverage, the summary's figures). :func:`run_pass` reads as that flow; :class:`~scanner_sim.survey.setup.PassSetup`
holds what is built once per pass and the stages chosen for it.

Reproducibility: every random draw is keyed by the pulse's slot number (sampling phase and ADC noise in
muls; navigation noise is a function of time), so a seed fixes a pass bit for bit whatever the chunk size.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from muls.infra.signals import stop_if_signalled
from scanner_sim import io
from scanner_sim.config import SceneConfig
from scanner_sim.config.crs import crs_label
from scanner_sim.io.rosbag import ROSBAG_NAME
from scanner_sim.io.run_dir import RunDirectory, abort_on_error
from scanner_sim.metrics.planned_swath import planned_swath
from scanner_sim.metrics.s44 import OrderTally
from scanner_sim.records.point_records import DropoutRecords, PointRecords
from scanner_sim.render import point_cloud
from scanner_sim.render.worker import PictureWorker
from scanner_sim.survey import pictures, provenance, sinks
from scanner_sim.survey.chunk import Chunk
from scanner_sim.survey.fan_out import SinkThreads
from scanner_sim.survey.gis_products import write_gis_products
from scanner_sim.survey.setup import PassOptions, PassPlan, PassSetup, check_pass_arguments
from scanner_sim.survey.tpu_calibration import UncertaintySink, single_pass_note
from scanner_sim.world.scene import Scene


@dataclass(frozen=True)
class PassResult:
    """What a pass returns: its summary (also written as summary.json by :func:`run_pass`), the folder of its
    outputs (None in memory), and, from :func:`simulate_pass`, the points, dropouts and trajectory."""

    summary: dict
    out_dir: Path | None = None
    points: PointRecords | None = None
    dropouts: DropoutRecords | None = None
    trajectory: dict | None = None

    def points_dataframe(self):
        """The points as a pandas DataFrame, one column per field (x_m, y_m, z_m for ``xyz``); needs the
        ``pandas`` extra."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("points_dataframe needs pandas: pip install 'muls-scanner[pandas]'") from None

        columns = {k: v for k, v in self.points.as_dict().items() if k != "xyz"}
        return pd.DataFrame({"x_m": self.points.xyz[:, 0], "y_m": self.points.xyz[:, 1],
                             "z_m": self.points.xyz[:, 2], **columns})

    def points_polydata(self):
        """The points as a pyvista ``PolyData`` with every field as point data."""
        return point_cloud.points_polydata(self.points)


@abort_on_error  # an unfinished run (an error, Ctrl-C, SIGTERM) leaves the output folder as it was
def run_pass(config: SceneConfig, out_dir: str | Path | None = None, options: PassOptions = PassOptions(),
             scene: Scene | None = None) -> PassResult:
    """Simulate the scene's pass and write its outputs in ``out_dir`` (default: the scene's output dir).

    The files are those of the pass's plan (:class:`~scanner_sim.survey.setup.PassPlan`): what the scene's
    ``output`` asks for (points.las and/or points.laz, or one per leg; trajectory.csv; waveforms.npz), dropouts.npz,
    and summary.json last. The summary's ``wall_s`` and ``pulses_per_s`` time the pass itself (chunks and sinks),
    ``setup_s`` the scene, BVH and tables built before it, ``compile_s`` the kernels compiled or loaded from the
    cache before it (:func:`warm_up`, and the set-up's ranging table, through which the physics kernels compile
    first: ``PassSetup.ranging_s``). A scene with a seabed also gets its coverage: the
    summary's ``coverage``, coverage_grid.npz and, when rendering, coverage_map.png. ``scene`` reuses a built scene.
    """
    if out_dir is not None and not isinstance(out_dir, (str, os.PathLike)):
        raise TypeError(f"out_dir must be a folder path (str or Path) or None, not {type(out_dir).__name__} {out_dir!r}")
    check_pass_arguments(config, options, scene)
    check_bag_dir(config.output.rosbag, Path(out_dir or config.output_dir))  # before the slow set-up
    with ExitStack() as stack:
        worker = picture_worker(PassPlan.of(config, options))
        if worker is not None:
            stack.enter_context(worker)  # an unfinished pass stops it
        t_setup = time.perf_counter()
        setup = PassSetup.build(config, options, scene)
        setup_s = time.perf_counter() - t_setup - setup.ranging_s
        run_dir = RunDirectory(out_dir or setup.config.output_dir).open()  # locked; written in a hidden sibling
        compile_s = setup.ranging_s + warm_up(setup, options)
        summary = stream_to_files(setup, run_dir.path, pass_chunks(setup, options), options, setup_s,
                                  compile_s=compile_s, worker=worker)
    return PassResult(summary, run_dir.commit())  # swapped in whole for the output folder (io/run_dir.py)


def simulate_pass(config: SceneConfig, options: PassOptions = PassOptions(), scene: Scene | None = None
                  ) -> PassResult:
    """Simulate the scene's pass in memory, writing no file: the result holds the points, the dropouts, the
    trajectory (:meth:`scanner_sim.motion.trajectory.Trajectory.table`) and the summary (with coverage over a
    seabed)."""
    t_setup = time.perf_counter()
    setup = PassSetup.build(config, options, scene)
    setup_s = time.perf_counter() - t_setup - setup.ranging_s
    compile_s = setup.ranging_s + warm_up(setup, options)
    memory, uncertainty = sinks.MemorySink(), UncertaintySink(setup.tpu)
    stats, coverage, wall_s = stream_pass(setup, pass_chunks(setup, options), [memory, uncertainty], options)
    dropouts = memory.dropouts()
    summary = sinks.pass_summary(pass_facts(setup, options), stats, stats.points, dropouts.counts_by_cause(), wall_s,
                                 setup_s, compile_s)
    summary["uncertainty"] = uncertainty_figures(setup, uncertainty, stats.pulses)
    if coverage is not None:
        summary["coverage"] = coverage.figures()
    return PassResult(summary, None, memory.points(), dropouts, trajectory_table(setup))


#: Pulse slots of the chunk :func:`warm_up` simulates and discards.
WARM_UP_SLOTS = 64


def warm_up(setup: PassSetup, options: PassOptions) -> float:
    """Compile every kernel of the pass's flow (numba compiles a kernel on its first call, about a minute for all of
    them on a fresh machine), or load it from the cache, before the pass's clock starts: simulate the pass's first
    :data:`WARM_UP_SLOTS` slots, and the whole records of one when the pass keeps some, and discard them, and load
    the coverage's S-44 tally, whose kernel runs in the sinks. Returns
    the seconds it took, the summary's ``compile_s``. A chunk is a pure function of its slots, so the pass's bits
    do not change."""
    started = time.perf_counter()
    first = next(iter(setup.slot_chunks()), None)
    if first is not None and first.size:
        setup.simulate_chunk(first[:WARM_UP_SLOTS])
        if options.waveforms or setup.config.output.waveform_every_n_pulses:
            setup.simulate_chunk(first[:1], record_mode="full", every_channel=True)
    load_sink_kernels(setup)
    return time.perf_counter() - started


def load_sink_kernels(setup: PassSetup) -> None:
    """Load (or compile) the kernels the pass runs in its sinks rather than in a chunk, which a warm-up chunk does
    not reach: the coverage's S-44 tally, when the pass measures coverage."""
    if setup.plan.measures_coverage:
        OrderTally.load_kernel()


def pass_facts(setup: PassSetup, options: PassOptions) -> sinks.PassFacts:
    """What made the pass, as its summary and files state it, its provenance with them (``options``: the pass's)."""
    config, level = setup.config, setup.level
    fingerprint = provenance.inputs_fingerprint(setup.given, options, level)
    far = [ch for ch in setup.model.instrument.channels if ch.gated]
    gate = (round(far[0].gate_delay_s * 1e9, 3), round(far[0].gate_width_s * 1e9, 3)) if far else (None, None)
    return sinks.PassFacts(
        scene=config.name, water=setup.water_name, seed=setup.seed, fidelity=level.name,
        instrument=setup.model.instrument.name, channels=tuple(ch.name for ch in setup.model.instrument.channels),
        record_mode=level.record_mode, subrays=setup.pattern.count, shadow_rays=level.shadow_rays,
        attenuation_model=setup.model.water.attenuation_model, multiple_scattering=setup.model.multiple_scattering,
        chunk_pulses=setup.config.survey.chunk_pulses, max_pulses=setup.max_pulses,
        scene_file=str(config.source_path) if config.source_path else None, altitude_m=config.platform.altitude_m,
        gate_delay_ns=gate[0], gate_width_ns=gate[1], crs=crs_label(config.crs), seabed=setup.scene.seabed_info,
        provenance=provenance.pass_provenance(config, setup.model.water, setup.model.instrument, level, fingerprint))


def trajectory_table(setup: PassSetup) -> dict[str, np.ndarray]:
    """The pass's true and estimated poses at the trajectory table's rate, over its slot range."""
    rate = setup.scanner.pulse_rate_hz
    return setup.trajectory.table(setup.first_slot / rate, setup.end_slot / rate)


def kept_slots(setup: PassSetup, count: int, every_n: int) -> np.ndarray:
    """Slots of the pulses whose whole records the pass keeps (waveforms.npz): ``count`` spread evenly over the pass,
    and every ``every_n``-th fired pulse (0: none of either)."""
    if not count and not every_n:
        return np.zeros(0, np.int64)
    slots = np.concatenate(list(setup.slot_chunks()))
    picks = [slots[::every_n]] if every_n else []
    if count:
        picks.append(slots[np.unique(np.linspace(0, slots.size - 1, min(count, slots.size)).astype(np.int64))])
    return np.unique(np.concatenate(picks))


def pass_chunk(setup: PassSetup, slots: np.ndarray, keep: np.ndarray) -> Chunk:
    """One chunk of pulse slots (n,) as a pass runs it: the whole flow, plus the whole records (every sample of
    every channel, the same noise) of its pulses among ``keep`` (sorted slots)."""
    chunk = setup.simulate_chunk(slots)
    mine = keep[np.isin(keep, slots)]
    if mine.size:
        kept = setup.simulate_chunk(mine, record_mode="full", every_channel=True).waveforms
        chunk = chunk._replace(kept_waveforms=(mine, kept))
    return chunk


#: Chunks a pass keeps in flight per worker: one running and one queued, so that workers finishing together (the
#: chunks of a round start together and cost alike) each find their next chunk queued, instead of waiting for the
#: pass's thread to take a finished chunk into its sinks before it submits the next. With one queued chunk in all
#: (workers + 1), a 30,000-pulse real_site pass at ``auto`` left a worker idle 5 to 9 ms at each round's end.
CHUNKS_IN_FLIGHT_PER_WORKER = 2


def pass_chunks(setup: PassSetup, options: PassOptions):
    """Every chunk of the pass through the flow, in order (:func:`pass_chunk`), under a progress bar with the
    pass's pulse count as its total.

    Chunks run side by side, one per core: each of :func:`chunk_workers` threads takes the next chunk and runs
    it whole (ray stage, then physics) on one numba thread; Embree and the kernels release the GIL. The pass's
    last round is cut in one part per worker (:func:`last_round_cut`). Each chunk is a pure function of its slots,
    so the bits do not depend on which thread ran it, how many there are or how the slots were cut; at most
    :data:`CHUNKS_IN_FLIGHT_PER_WORKER` chunks a worker are in flight. A Ctrl-C or SIGTERM whose first raise Python
    dropped stops the pass at its next chunk (:func:`~muls.infra.signals.stop_if_signalled`).
    """
    keep = kept_slots(setup, options.waveforms, setup.config.output.waveform_every_n_pulses)
    # The total counts every fired slot of the pass (6 ms on real_site): only for a bar that shows it.
    bar = tqdm(total=setup.expected_pulses() if options.progress else None, unit="pulse", unit_scale=True,
               disable=not options.progress, desc=setup.config.name)
    workers = chunk_workers()
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="chunk") as pool:
        in_flight: deque[Future] = deque()
        for slots in last_round_cut(setup.slot_chunks(), workers):
            stop_if_signalled()
            in_flight.append(pool.submit(_whole_chunk, setup, slots, keep))
            if len(in_flight) >= CHUNKS_IN_FLIGHT_PER_WORKER * workers:
                yield _finished(in_flight.popleft(), bar)
        while in_flight:
            yield _finished(in_flight.popleft(), bar)
    bar.close()


def last_round_cut(chunks, parts: int):
    """``chunks`` (arrays of slots) as they come, the pass's last round cut into ``parts`` near-equal chunks, so that
    the cores share the pass's end instead of some running its last chunks alone while the others wait (the bits do
    not depend on the cut).

    The last round is what follows the pass's last whole round of ``parts`` chunks: the last ``K mod parts``
    chunks of K, or the last chunk alone when K is a multiple of ``parts``. A last chunk under half the size of the
    one before it (the few pulses a pass's ``max_pulses`` leaves after a whole chunk) is counted with that one. Three
    chunks on two workers thus end in two halves of the third: the pass takes one and a half chunks' time, not two
    with one core idle for the last."""
    held: list[np.ndarray] = []  # the last ``parts`` chunks, handed on once a later one shows they are not the last
    handed = 0
    for chunk in chunks:
        held.append(chunk)
        if len(held) > parts:
            handed += 1
            yield held.pop(0)
    if len(held) > 1 and 2 * held[-1].size < held[-2].size:
        held[-2:] = [np.concatenate(held[-2:])]
    last = (handed + len(held)) % parts or 1
    yield from held[:len(held) - last]
    if held:
        tail = np.concatenate(held[len(held) - last:])
        yield from (part for part in np.array_split(tail, parts) if part.size)


#: Chunk workers from which a pass's sinks take their chunks on threads of their own. With fewer, the chunks keep
#: every core busy and the sinks' threads only take cores from them: on 2 cores, sinks on threads made ``fast`` 7 %
#: and ``balanced`` 3 % slower in pulses/s than sinks on the pass's thread (``scanner-sim bench --json``, the two
#: alternated twice); from about 4 cores their serial time starts to bound the pass (docs/performance.md, "Cores").
SINK_THREADS_FROM_WORKERS = 4


def chunk_workers() -> int:
    """Chunks a pass runs side by side: numba's thread count (the cores, unless ``NUMBA_NUM_THREADS`` or
    ``numba.set_num_threads`` says fewer)."""
    return numba.get_num_threads()


def _whole_chunk(setup: PassSetup, slots: np.ndarray, keep: np.ndarray) -> Chunk:
    # One numba thread per chunk (numba's count is per thread): the chunks beside it keep the other cores busy,
    # and more threads than cores would only evict each other's caches.
    numba.set_num_threads(1)
    return pass_chunk(setup, slots, keep)


def _finished(chunk: Future, bar) -> Chunk:
    done = chunk.result()
    bar.update(done.slots.size)
    return done


def uncertainty_figures(setup: PassSetup, sink, pulses: int) -> dict:
    """The summary's ``uncertainty`` (the sink's figures), its calibration with a ``note`` on what one pass of
    ``pulses`` can show (:func:`~scanner_sim.survey.tpu_calibration.single_pass_note`)."""
    figures = sink.figures()
    flown_s = pulses / (setup.scanner.pulse_rate_hz * setup.scanner.active_fraction)
    figures["calibration"]["note"] = single_pass_note(flown_s, setup.config.platform.navigation_noise)
    return figures


def stream_pass(setup: PassSetup, chunks, chunk_sinks: list, options: PassOptions, sink_threads: bool | None = None):
    """``chunks`` into ``chunk_sinks``, plus the running figures and, when the pass measures coverage, its tally, in
    the pass's order (:class:`~scanner_sim.survey.fan_out.SinkThreads`): each sink on its own thread when
    ``sink_threads`` is true, all on the caller's thread when false (for a profile of it); by default on threads from
    :data:`SINK_THREADS_FROM_WORKERS` chunk workers. Returns (stats, coverage sink or None, wall seconds)."""
    coverage = None
    if setup.plan.measures_coverage:
        planned = planned_swath(setup.config, setup.trajectory, setup.scanner.pulse_rate_hz)
        coverage = sinks.CoverageSink(setup.scene, options.coverage, planned)
    stats = sinks.PassStats(len(setup.model.instrument.channels), setup.scene.heightfield)
    every = [*chunk_sinks, stats] + ([coverage] if coverage is not None else [])
    if sink_threads is None:
        sink_threads = chunk_workers() >= SINK_THREADS_FROM_WORKERS
    started = time.perf_counter()
    with SinkThreads(every, threads=sink_threads) as fan:
        for chunk in chunks:
            fan.add(chunk)
        fan.finish()
    return stats, coverage, time.perf_counter() - started


def check_bag_dir(bag, final: Path) -> None:
    """Refuse (ValueError, one line) a bag folder ``bag.dir`` in the run's folder ``final`` or holding it: the run
    replaces its folder whole."""
    if bag is None or bag.dir is None:
        return
    there, run = Path(os.path.abspath(bag.dir)), Path(os.path.abspath(final))
    if there == run or run in there.parents or there in run.parents:
        raise ValueError(f"output.rosbag.dir = {bag.dir!r}: lies in the output folder {str(final)!r} or holds it, "
                         f"which a run replaces whole; leave it out to write the bag as {str(final / ROSBAG_NAME)!r}")


def bag_sinks(setup: PassSetup, out: Path, facts: sinks.PassFacts) -> list:
    """The ROS 2 bag the scene's ``output.rosbag`` asks for (none when absent), in ``out/rosbag`` or its own ``dir``."""
    bag, trajectory = setup.config.output.rosbag, setup.trajectory
    if bag is None:
        return []

    def poses_at(times_s):
        truth = trajectory.poses(times_s)
        return truth, trajectory.estimate_of(truth)

    return [sinks.RosbagSink(Path(bag.dir) if bag.dir else out / ROSBAG_NAME, bag, setup.scene.local_origin,
                             setup.scanner.line_index, poses_at, (0.0, trajectory.duration_s), setup.scanner.pulse_rate_hz,
                             setup.scanner.mount_position_m, facts.metadata())]


def stream_to_files(setup: PassSetup, out: Path, chunks, options: PassOptions, setup_s: float,
                    earlier_wall_s: float = 0.0, compile_s: float = 0.0, worker: PictureWorker | None = None) -> dict:
    """``chunks`` of the pass streamed into the files of its plan in ``out`` (what the scene's ``output`` asks
    for, dropouts, coverage grid, trajectory, scene, waveforms, pictures), summary.json last; returns the summary.
    ``earlier_wall_s``: seconds already spent simulating the chunks elsewhere (a pass split in segments), added to
    ``wall_s``; ``compile_s``: seconds :func:`warm_up` took, reported apart; ``worker``: the child process that draws
    the pictures while this one writes the rest (:func:`picture_worker`; None: drawn here)."""
    facts, files, output = pass_facts(setup, options), setup.plan.files, setup.config.output
    render = "render.png" in files
    draw = pictures.draw_here if worker is None else worker.draw
    if render and worker is not None:  # the child builds the plotter and the mesh while the pass runs
        pictures.prepare_render(setup.scene, options.render_size, draw)
    with ExitStack() as stack:
        clouds = [stack.enter_context(sink) for sink in
                  sinks.point_cloud_sinks(output, out, setup.scene.local_origin, facts.metadata(), setup.scene.crs)]
        clouds += [stack.enter_context(sink) for sink in bag_sinks(setup, out, facts)]
        dropouts = stack.enter_context(sinks.DropoutSink(out / "dropouts.npz"))
        waveforms = sinks.WaveformSink(setup.model.instrument.digitizer, facts.channels)
        sample, uncertainty = pictures.CloudSample(), UncertaintySink(setup.tpu)
        stats, coverage, wall_s = stream_pass(setup, chunks, [*clouds, dropouts, waveforms, uncertainty]
                                              + ([sample] if render else []), options)
        if render:  # first: drawn beside the point clouds' closing and the files below
            pictures.render_points(out / "render.png", sample, setup.scene, facts, options.render_size, draw,
                                   prepared=worker is not None)
    summary = sinks.pass_summary(facts, stats, stats.points, dropouts.counts_by_cause(), wall_s + earlier_wall_s,
                                 setup_s, compile_s)
    summary["uncertainty"] = uncertainty_figures(setup, uncertainty, stats.pulses)
    if coverage is not None:
        summary["coverage"] = coverage.write(out / "coverage_grid.npz")
    if "coverage_map.png" in files:
        pictures.render_coverage_map(out / "coverage_map.png", coverage, setup.scene, facts, summary["coverage"], draw)
    if "s44_map.png" in files:
        pictures.render_order_map(out / "s44_map.png", coverage, facts, summary["coverage"], draw)
    if "scene.ply" in files:
        scene = setup.scene
        io.write_scene_ply(out / "scene.ply", scene.vertices, scene.faces, scene.face_label, scene.face_object)
    crs = setup.scene.crs
    table = trajectory_table(setup) if output.trajectory_csv or crs is not None else None
    if output.trajectory_csv:
        sinks.write_trajectory(out, table, output.split_legs)
    if crs is not None:
        write_gis_products(out, crs, coverage, table, setup.trajectory.waypoints_xy_m)
    if "waveforms.npz" in files:
        waveforms.write(out / "waveforms.npz")
    if worker is not None:
        worker.finish()
    io.write_summary_json(out / "summary.json", summary)  # last: a complete pass is one with a summary
    return summary


def picture_worker(plan: PassPlan) -> PictureWorker | None:
    """A :class:`~scanner_sim.render.worker.PictureWorker` for the pictures of ``plan``, started now so that it
    loads its libraries while the pass is set up; None when the plan has no picture, or when this process may
    not start one (a daemonic process, such as a multiprocessing pool's worker: its pictures are drawn in it)."""
    three_d = "render.png" in plan.files
    if not (three_d or "coverage_map.png" in plan.files) or multiprocessing.current_process().daemon:
        return None
    return PictureWorker(three_d)
