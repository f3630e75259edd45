"""A survey pass end to end: chunks of pulses flow through poses, mirror directions, beam sub-rays, hits and
the receiver check, the MULS waveforms and ranging, then georeferencing, and on to the sinks (LAS, dropouts,
coverage, the summary's figures). :func:`run_pass` reads as that flow; :class:`PassSetup` holds what is
built once per pass.

Reproducibility: every random draw is keyed by the pulse's slot number (sampling phase and ADC noise in
muls; navigation noise is a function of time), so a seed fixes a pass bit for bit whatever the chunk size.
"""

from __future__ import annotations

import math
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numba
import numpy as np
from tqdm import tqdm

from muls.radiometry import background_power_w
from muls.simulate import simulate
from muls.waveform import OpticalModel, PulseBatch
from scanner_sim import io
from scanner_sim.config import SceneConfig
from scanner_sim.fidelity import FidelityLevel, column_cuts
from scanner_sim.io.run_dir import RunDirectory, abort_on_error
from scanner_sim.metrics.coverage import CoverageSettings, Footprint, nominal_footprint
from scanner_sim.motion.scanner import Scanner
from scanner_sim.motion.track_checks import build_trajectory
from scanner_sim.motion.trajectory import Poses, Trajectory
from scanner_sim.rays.auto import cast_auto
from scanner_sim.rays.beams import BeamPattern, beam_pattern
from scanner_sim.rays.cast import Hits, RayCaster, cast_beams
from scanner_sim.rays.seabed_grid import seabed_grid_of
from scanner_sim.render import viz
from scanner_sim.survey import sinks
from scanner_sim.survey.georeference import LinesOfSight, georeference
from scanner_sim.survey.point_records import DropoutRecords, PointRecords
from scanner_sim.world.scene import Scene, build_scene


@dataclass(frozen=True)
class PassOptions:
    """How to run a pass. ``water``, ``seed``, ``fidelity``, ``max_pulses`` and ``chunk_pulses`` override the
    scene's keys (None keeps the scene's value) and are validated like them; the rest choose the outputs."""

    water: str | None = None
    seed: int | None = None
    fidelity: str | None = None
    max_pulses: int | None = None
    chunk_pulses: int | None = None
    waveforms: int = 0
    progress: bool = True
    render: bool = True
    render_size: tuple[int, int] = (1600, 1000)
    write_scene: bool = True
    coverage: CoverageSettings = CoverageSettings()

    def scene_overrides(self) -> dict[str, Any]:
        """The scene keys these options set, by dotted name."""
        keys = {"water": self.water, "survey.seed": self.seed, "survey.fidelity": self.fidelity,
                "survey.max_pulses": self.max_pulses, "survey.chunk_pulses": self.chunk_pulses}
        return {k: v for k, v in keys.items() if v is not None}


class RayStage(NamedTuple):
    """A chunk after its ray stage: pulse slots (n,), the sub-ray hits, the muls input built from them, each
    pulse's estimated line of sight with the truth along it, and the nominal footprint (None unless asked for)."""

    slots: np.ndarray
    hits: Hits
    batch: PulseBatch
    sight: LinesOfSight
    footprint: Footprint | None


class Chunk(NamedTuple):
    """One chunk through the flow: its pulse slots (n,), points, dropouts, the muls records, and the nominal
    beam footprint (None unless asked for)."""

    slots: np.ndarray
    points: PointRecords
    dropouts: DropoutRecords
    records: object
    footprint: Footprint | None


@dataclass(frozen=True)
class PassSetup:
    """What a pass builds once: the scene and its ray caster, trajectory, scanner, the instrument in its
    water, the fidelity level and its sub-ray pattern, and the pass's slot range."""

    config: SceneConfig
    scene: Scene
    caster: RayCaster
    trajectory: Trajectory
    scanner: Scanner
    model: OpticalModel
    level: FidelityLevel
    pattern: BeamPattern
    first_slot: int
    end_slot: int
    water_name: str = field(default="")

    @classmethod
    def build(cls, config: SceneConfig, options: PassOptions = PassOptions(), scene: Scene | None = None
              ) -> PassSetup:
        """``scene``: the already built :class:`Scene` of ``config`` to reuse, if any."""
        config = config.with_overrides(options.scene_overrides())
        survey = config.survey
        water = config.water_model()
        model = OpticalModel.build(config.instrument.to_instrument(water), water)
        scene = build_scene(config) if scene is None else scene
        caster = RayCaster.for_scene(scene)  # the Embree BVH is built here: set-up, not part of the pass
        seabed_grid_of(caster, scene)  # and the seabed's proof grid, kept on the caster (None: no height field)
        trajectory = build_trajectory(config, scene)
        scanner = Scanner.from_config(config.scanner, model.instrument)
        level = survey.level
        rate = scanner.pulse_rate_hz
        duration = survey.duration_s if survey.duration_s is not None else trajectory.duration_s
        return cls(config, scene, caster, trajectory, scanner, model, level,
                   beam_pattern(level.subrays, survey.beam_profile), math.ceil(survey.start_s * rate - 1e-9),
                   math.ceil((survey.start_s + duration) * rate - 1e-9), config.water.preset or water.name)

    @property
    def seed(self) -> int:
        return self.config.survey.seed

    @property
    def max_pulses(self) -> int | None:
        return self.config.survey.max_pulses

    @property
    def chunk_slots(self) -> int:
        return self.config.survey.chunk_pulses

    def expected_pulses(self) -> int:
        n = int((self.end_slot - self.first_slot) * self.scanner.active_fraction)
        return min(n, self.max_pulses) if self.max_pulses else n

    def slot_chunks(self):
        """Yield (n,) int64 slot numbers of the fired pulses, ``chunk_slots`` slots at a time."""
        rate, fired = self.scanner.pulse_rate_hz, 0
        for k0 in range(self.first_slot, self.end_slot, self.chunk_slots):
            k1 = min(self.end_slot, k0 + self.chunk_slots)
            slots = self.scanner.pulse_slots(k0 / rate, k1 / rate)
            if self.max_pulses is not None:
                slots = slots[: self.max_pulses - fired]
            if slots.size:
                fired += slots.size
                yield slots
            if self.max_pulses is not None and fired >= self.max_pulses:
                return

    def cast_chunk(self, slots: np.ndarray, footprint: bool = False) -> RayStage:
        """The ray stage of one chunk of pulse slots (n,): poses, mirror directions, beam sub-rays and their hits,
        the muls input, each pulse's estimated line of sight with the truth along it, and (``footprint``) the
        nominal beam footprint that coverage needs. Only Embree and ray kernels that release the GIL: it runs
        in a thread beside the physics of the chunk before (:func:`pass_chunks`)."""
        poses = self.trajectory.poses(slots / self.scanner.pulse_rate_hz)
        beam_o, beam_d, shaft, rx_o, rx_d = self.scanner.world_rays(poses)
        cast = cast_auto if self.level.adaptive else cast_beams
        hits = cast(self.caster, self.scene, beam_o, beam_d, shaft, rx_o, rx_d, self.pattern,
                    self.model.instrument.geometry, self.level.shadow_rays)
        batch = pulse_batch(hits, slots, self.model, self.config.water.background_radiance_w_m2_sr_nm,
                            self.level.column_cut)
        return RayStage(slots, hits, batch, self.lines_of_sight(slots, poses, hits, (beam_o, beam_d)),
                        nominal_footprint(hits) if footprint else None)

    def finish_chunk(self, stage: RayStage, record_mode: str | None = None, every_channel: bool = False,
                     whole_records: bool = False) -> Chunk:
        """The physics of a chunk after its ray stage: MULS waveforms and ranging, georeferencing, dropouts.
        ``record_mode`` and ``every_channel`` override the level's record mode and its ``deciding_only`` (for
        records kept whole, as waveforms.npz keeps them). Unless ``every_channel`` or ``whole_records``, only the
        samples the ranging reads are synthesised (the same points, :func:`muls.detection.digitise`'s
        ``ranging_only``): of each CH0 record the span of its peak, and of a full record the samples the peak
        search may read."""
        records, ranging = simulate(self.model, stage.batch, self.seed, record_mode or self.level.record_mode,
                                    deciding_only=self.level.deciding_only and not every_channel,
                                    ranging_only=not (every_channel or whole_records))
        sight, lost = stage.sight, ranging.dropout_cause >= 0
        dropouts = DropoutRecords(pulse_index=stage.slots[lost], time_s=sight.time_s[lost], origin=sight.origin_m[lost],
                                  direction=sight.direction[lost], cause=ranging.dropout_cause[lost].astype(np.uint8))
        return Chunk(stage.slots, georeference(ranging, stage.hits, sight), dropouts, records, stage.footprint)

    def simulate_chunk(self, slots: np.ndarray, record_mode: str | None = None, footprint: bool = False,
                       every_channel: bool = False, whole_records: bool = False) -> Chunk:
        """One chunk of pulse slots (n,) through the whole flow; ``footprint``: also the nominal beam footprint
        that coverage needs (None otherwise); ``record_mode``, ``every_channel``, ``whole_records``: as
        :meth:`finish_chunk`."""
        return self.finish_chunk(self.cast_chunk(slots, footprint), record_mode, every_channel, whole_records)

    def lines_of_sight(self, slots: np.ndarray, poses: Poses, hits: Hits,
                       true_beam: tuple[np.ndarray, np.ndarray]) -> LinesOfSight:
        """Each pulse's estimated beam, with the first truth surface along it. Without navigation noise the
        estimated beam is the true beam axis (``true_beam``: its origins and directions (n, 3), as the ray stage
        cast them from the true ``poses``), whose first hit the beam cast already holds (sub-ray 0 of every pattern is
        the axis), so only a noisy navigation needs its estimated poses, its beam and a cast of its own."""
        noisy, times = self.trajectory.has_navigation_noise, poses.time_s
        if noisy:
            origin, direction = self.scanner.beam_rays(self.trajectory.estimate_of(poses))
        else:
            origin, direction = true_beam
        true_range, first_object = np.full(slots.size, np.nan), np.full(slots.size, -1)
        if noisy:
            ray, tri, dist = self.caster.first_hits((origin - self.scene.local_origin).astype(np.float32),
                                                    direction.astype(np.float32))
            true_range[ray], first_object[ray] = dist, self.scene.face_object[tri]
        else:
            axis = hits.subray_index == 0
            true_range[hits.pulse_index[axis]] = hits.range_m[axis]
            first_object[hits.pulse_index[axis]] = hits.object_id[axis]
        return LinesOfSight(origin, direction, true_range, first_object,
                            np.degrees(self.scanner.scan_angle_rad(times)), times, slots, self.trajectory.leg(times))


def hit_echo_range_m(hits: Hits) -> np.ndarray:
    """(n,) range [m] that times each hit's echo: half the path laser -> hit -> receiver aperture."""
    return 0.5 * (hits.range_m + hits.rx_distance_m)


def pulse_batch(hits: Hits, slots: np.ndarray, model: OpticalModel, background_radiance: float = 0.0,
                column_cut: str = "pulse") -> PulseBatch:
    """The muls input of a chunk: one echo per sub-ray hit (return i is hit i), the column cut where the
    beam's energy stops, and the background light.

    Echo weight (Eq. 7 per sub-ray): w_j (rho_j / pi) cos(theta_j) x receiver weight. The column of the
    footprint is cut as ``column_cut`` says (:func:`scanner_sim.fidelity.column_cuts`: once per pulse at the
    energy-weighted mean hit range, or per sub-ray), and runs to the record's end for the share that misses.
    The background (Eqs. 8-10) of artificial light of spectral radiance ``background_radiance``
    [W/(m^2 sr nm)] sees the footprint's mean range and reflectance.
    """
    n = slots.shape[0]
    echo_range = hit_echo_range_m(hits)
    weight = hits.weight * hits.reflectance / np.pi * np.cos(hits.incidence_rad) * hits.receiver_weight
    cuts, shares = column_cuts(hits.pulse_index, hits.range_m, hits.weight, n, column_cut)
    background = np.zeros(n)
    if background_radiance > 0.0:
        hit_share = np.bincount(hits.pulse_index, weights=hits.weight, minlength=n)
        mean_range = np.bincount(hits.pulse_index, weights=hits.weight * hits.range_m, minlength=n)
        mean_range = np.divide(mean_range, hit_share, out=np.full(n, np.inf), where=hit_share > 0)
        rho = np.bincount(hits.pulse_index, weights=hits.weight * hits.reflectance, minlength=n)
        rho = np.divide(rho, hit_share, out=np.zeros(n), where=hit_share > 0)
        background = background_power_w(model.instrument, model.water, background_radiance, mean_range, rho)
    return PulseBatch(pulse_id=slots, return_pulse=hits.pulse_index, return_range_m=echo_range,
                      return_weight_per_sr=weight, column_cut_m=cuts, column_cut_weight=np.clip(shares, 0.0, 1.0),
                      background_w=background)


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
        return viz.points_polydata(self.points)


@abort_on_error  # an unfinished run (an error, Ctrl-C, SIGTERM) leaves the output folder as it was
def run_pass(config: SceneConfig, out_dir: str | Path | None = None, options: PassOptions = PassOptions(),
             scene: Scene | None = None) -> PassResult:
    """Simulate the scene's pass and write its outputs in ``out_dir`` (default: the scene's output dir).

    The scene's ``output`` section says what is written (points.las and/or points.laz, or one per leg;
    trajectory.csv; waveforms.npz); dropouts.npz and summary.json always are, the summary last. The summary's
    ``wall_s`` and ``pulses_per_s`` time the pass itself (chunks and sinks), ``setup_s`` the scene, BVH and
    tables built before it. A scene with a seabed also gets its coverage: the summary's ``coverage``,
    coverage_grid.npz and, when rendering, coverage_map.png. ``scene`` reuses a built scene.
    """
    t_setup = time.perf_counter()
    setup = PassSetup.build(config, options, scene)
    setup_s = time.perf_counter() - t_setup
    run_dir = RunDirectory(out_dir or setup.config.output_dir).open()  # locked; written in a hidden sibling
    summary = stream_to_files(setup, run_dir.path, pass_chunks(setup, options), options, setup_s)
    return PassResult(summary, run_dir.commit())  # swapped in whole for the output folder (io/run_dir.py)


def simulate_pass(config: SceneConfig, options: PassOptions = PassOptions(), scene: Scene | None = None
                  ) -> PassResult:
    """Simulate the scene's pass in memory, writing no file: the result holds the points, the dropouts, the
    trajectory (:func:`scanner_sim.survey.sinks.trajectory_table`) and the summary (with coverage over a seabed)."""
    t_setup = time.perf_counter()
    setup = PassSetup.build(config, options, scene)
    setup_s = time.perf_counter() - t_setup
    memory = sinks.MemorySink()
    stats, coverage, wall_s = stream_pass(setup, pass_chunks(setup, options), [memory], options)
    dropouts = memory.dropouts()
    summary = sinks.pass_summary(setup, stats, stats.points, dropouts.counts_by_cause(), wall_s, setup_s)
    if coverage is not None:
        summary["coverage"] = coverage.figures()
    return PassResult(summary, None, memory.points(), dropouts, sinks.trajectory_table(setup))


def point_cloud_sinks(setup: PassSetup, out: Path) -> list:
    """The point-cloud writers the scene's ``output`` asks for: points.las and/or points.laz, or one file per
    leg of each, every one carrying the pass's metadata."""
    output, origin, metadata = setup.config.output, setup.scene.local_origin, sinks.pass_metadata(setup)
    suffixes = [s for s, on in ((".las", output.las), (".laz", output.laz)) if on]
    if output.split_legs:
        return [sinks.LegLasSink(out, s, origin, metadata) for s in suffixes]
    return [sinks.LasSink(out / f"points{s}", origin, metadata) for s in suffixes]


def pass_chunks(setup: PassSetup, options: PassOptions):
    """Every chunk of the pass through the flow, in order (with the nominal footprint where coverage needs it),
    under a progress bar with the pass's pulse count as its total.

    Chunks run side by side, one per core: each of :func:`chunk_workers` threads takes the next chunk and runs
    it whole (ray stage, then physics) on one numba thread; Embree and the kernels release the GIL. The last chunk
    is cut in one part per worker (:func:`last_cut`). Each chunk is a pure function of its slots, so the bits do
    not depend on which thread ran it, how many there are or how the slots were cut; at most one chunk more than
    there are workers is in flight.
    """
    footprint = setup.scene.heightfield is not None
    bar = tqdm(total=setup.expected_pulses(), unit="pulse", unit_scale=True, disable=not options.progress,
               desc=setup.config.name)
    workers = chunk_workers()
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="chunk") as pool:
        in_flight: deque[Future] = deque()
        for slots in last_cut(setup.slot_chunks(), workers):
            in_flight.append(pool.submit(_whole_chunk, setup, slots, footprint))
            if len(in_flight) > workers:
                yield _finished(in_flight.popleft(), bar)
        while in_flight:
            yield _finished(in_flight.popleft(), bar)
    bar.close()


def last_cut(chunks, parts: int):
    """``chunks`` (arrays of slots) as they come, the last one cut into ``parts`` near-equal chunks, so that the
    cores share the pass's end instead of one running its last chunk alone (the bits do not depend on the cut)."""
    current = next(chunks, None)
    for following in chunks:
        yield current
        current = following
    if current is not None:
        yield from (part for part in np.array_split(current, parts) if part.size)


def chunk_workers() -> int:
    """Chunks a pass runs side by side: numba's thread count (the cores, unless ``NUMBA_NUM_THREADS`` or
    ``numba.set_num_threads`` says fewer)."""
    return numba.get_num_threads()


def _whole_chunk(setup: PassSetup, slots: np.ndarray, footprint: bool) -> Chunk:
    # One numba thread per chunk (numba's count is per thread): the chunks beside it keep the other cores busy,
    # and more threads than cores would only evict each other's caches.
    numba.set_num_threads(1)
    return setup.simulate_chunk(slots, footprint=footprint)


def _finished(chunk: Future, bar) -> Chunk:
    done = chunk.result()
    bar.update(done.slots.size)
    return done


def stream_pass(setup: PassSetup, chunks, chunk_sinks: list, options: PassOptions):
    """``chunks`` into ``chunk_sinks``, plus the running figures and, over a seabed, coverage. Returns (stats,
    coverage sink or None, wall seconds)."""
    coverage = sinks.CoverageSink(setup.scene, options.coverage) if setup.scene.heightfield is not None else None
    stats = sinks.PassStats(len(setup.model.instrument.channels))
    every = [*chunk_sinks, stats] + ([coverage] if coverage is not None else [])
    started = time.perf_counter()
    for chunk in chunks:
        for sink in every:
            sink.add(chunk)
    return stats, coverage, time.perf_counter() - started


def stream_to_files(setup: PassSetup, out: Path, chunks, options: PassOptions, setup_s: float,
               earlier_wall_s: float = 0.0) -> dict:
    """``chunks`` of the pass streamed into its files in ``out`` (what the scene's ``output`` asks for, dropouts,
    coverage grid, trajectory, scene, renders), summary.json last; returns the summary. ``earlier_wall_s``:
    seconds already spent simulating the chunks elsewhere (a pass split in segments), added to ``wall_s``."""
    with ExitStack() as stack:
        clouds = [stack.enter_context(sink) for sink in point_cloud_sinks(setup, out)]
        dropouts = stack.enter_context(sinks.DropoutSink(out / "dropouts.npz"))
        stats, coverage, wall_s = stream_pass(setup, chunks, [*clouds, dropouts], options)
    summary = sinks.pass_summary(setup, stats, stats.points, dropouts.counts_by_cause(), wall_s + earlier_wall_s,
                                 setup_s)
    if coverage is not None:
        summary["coverage"] = coverage.write(out / "coverage_grid.npz")
    sinks.write_pass_files(setup, out, options)
    if options.render and clouds:
        sinks.render_pass(setup, clouds[0], out, options.render_size)
        if coverage is not None:
            sinks.render_coverage_map(setup, coverage, out / "coverage_map.png", summary)
    io.write_summary_json(out / "summary.json", summary)  # last: a complete pass is one with a summary
    return summary
