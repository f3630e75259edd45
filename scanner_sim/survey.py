"""A survey pass end to end (DESIGN.md section 2): chunks of pulses flow through poses, mirror directions,
beam sub-rays, hits and the receiver check, the MULS waveforms and ranging, then georeferencing, and stream
to disk. :func:`run_pass` reads as that flow; :class:`PassSetup` holds what is built once per pass.

Reproducibility: every random draw is keyed by the pulse's slot number (sampling phase and ADC noise in
muls; navigation noise is a function of time), so a seed fixes a pass bit for bit whatever the chunk size.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from muls.detection import ChannelArrays
from muls.ranging import DROPOUT_CAUSES
from muls.radiometry import target_factor
from muls.simulate import simulate
from muls.water import water_preset
from muls.waveform import OpticalModel, PulseBatch

from .beams import FIDELITY, beam_pattern
from .config import SceneConfig
from .coverage import CoverageAccumulator, CoverageSettings, Footprint, nominal_footprint
from .points import intensity_from_power, match_returns_to_hits
from .records import DropoutRecords, PointRecords
from .raycast import Hits, cast_beams
from .scanner import Scanner
from .scene import build_scene
from .trajectory import build_trajectory

#: Record mode of each fidelity level: echo windows, or every sample of every channel.
RECORD_MODE = {"fast": "windowed", "balanced": "windowed", "reference": "full"}

#: Resolution and extent of the streaming |range error| histogram behind the summary's quantiles [m].
ERROR_BIN_M = 5e-4
ERROR_MAX_M = 20.0

#: Trajectory output rate [Hz].
TRAJECTORY_RATE_HZ = 10.0


@dataclass(frozen=True)
class PassOptions:
    """Command-line overrides of a scene's settings; None keeps the scene's value."""

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


class Chunk(NamedTuple):
    """One chunk through the flow: points, dropouts, the muls records, and the nominal beam footprint."""

    points: PointRecords
    dropouts: DropoutRecords
    records: object
    footprint: Footprint | None


@dataclass
class PassSetup:
    """What a pass builds once: scene, trajectory, scanner, instrument in its water, sub-ray pattern."""

    config: SceneConfig
    scene: object
    trajectory: object
    scanner: Scanner
    model: OpticalModel
    pattern: object
    shadow_rays: bool
    record_mode: str
    seed: int
    fidelity: str
    water_name: str
    first_slot: int
    end_slot: int
    max_pulses: int | None
    chunk_slots: int

    @classmethod
    def build(cls, config: SceneConfig, options: PassOptions = PassOptions(), scene=None) -> "PassSetup":
        """``scene``: the already built :class:`scanner_sim.scene.Scene` of ``config`` to reuse, if any."""
        survey = config.survey
        fidelity = options.fidelity or survey.fidelity
        if fidelity not in FIDELITY:
            raise ValueError(f"fidelity = {fidelity!r}: must be one of {', '.join(FIDELITY)}")
        water = water_preset(options.water) if options.water else config.water_model()
        instrument = config.instrument.to_instrument(water)
        model = OpticalModel.build(instrument, water)
        scene = build_scene(config) if scene is None else scene
        scene.caster()  # build the Embree BVH now: set-up, not part of the pass
        trajectory = build_trajectory(config, scene)
        scanner = Scanner.from_config(config.scanner, instrument)
        subrays = survey.subrays if survey.subrays is not None else FIDELITY[fidelity]["subrays"]
        shadow = survey.shadow_rays if survey.shadow_rays is not None else FIDELITY[fidelity]["shadow_rays"]
        rate = scanner.pulse_rate_hz
        duration = survey.duration_s if survey.duration_s is not None else trajectory.duration_s
        chunk = options.chunk_pulses or survey.chunk_pulses
        if chunk < 1:
            raise ValueError(f"chunk_pulses = {chunk!r}: must be a positive integer")
        max_pulses = options.max_pulses if options.max_pulses is not None else survey.max_pulses
        if max_pulses is not None and max_pulses < 1:
            raise ValueError(f"max_pulses = {max_pulses!r}: must be a positive integer")
        seed = options.seed if options.seed is not None else survey.seed
        if seed < 0:
            raise ValueError(f"seed = {seed!r}: must be a non-negative integer")
        return cls(config, scene, trajectory, scanner, model, beam_pattern(subrays, survey.beam_profile), shadow,
                   RECORD_MODE[fidelity], seed, fidelity, options.water or config.water.preset or water.name,
                   math.ceil(survey.start_s * rate - 1e-9), math.ceil((survey.start_s + duration) * rate - 1e-9),
                   max_pulses, chunk)

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

    def simulate_chunk(self, slots: np.ndarray, record_mode: str | None = None, footprint: bool = False) -> Chunk:
        """One chunk of pulse slots (n,) through the whole flow; ``footprint``: also the nominal beam footprint
        that coverage needs (None otherwise)."""
        times = slots / self.scanner.pulse_rate_hz
        true_poses = self.trajectory.poses(times)
        beam_o, beam_d, shaft, rx_o, rx_d = self.scanner.world_rays(true_poses)
        hits = cast_beams(self.scene, beam_o, beam_d, shaft, rx_o, rx_d, self.pattern,
                          self.model.instrument.geometry, self.shadow_rays)
        batch = pulse_batch(hits, slots, self.model)
        records, ranging = simulate(self.model, batch, self.seed, record_mode or self.record_mode)
        est_o, est_d, _, _, _ = self.scanner.world_rays(self.trajectory.poses(times, estimated=True))
        points = georeference(self, ranging, hits, batch, slots, times, est_o, est_d)
        lost = ranging.dropout_cause >= 0
        dropouts = DropoutRecords(pulse_index=slots[lost], time_s=times[lost], origin=est_o[lost],
                                  direction=est_d[lost], cause=ranging.dropout_cause[lost].astype(np.uint8))
        return Chunk(points, dropouts, records, nominal_footprint(self.scene, beam_o, beam_d) if footprint else None)


def hit_echo_range_m(hits: Hits) -> np.ndarray:
    """(n,) range [m] that times each hit's echo: half the path laser -> hit -> receiver aperture."""
    return 0.5 * (hits.range_m + hits.rx_distance_m)


def pulse_batch(hits: Hits, slots: np.ndarray, model: OpticalModel) -> PulseBatch:
    """The muls input of a chunk: one echo per sub-ray hit, the column cut where the beam's energy stops.

    Echo weight (Eq. 7 per sub-ray): w_j (rho_j / pi) cos(theta_j) x receiver weight. The column of the
    footprint is cut at the energy-weighted mean hit range for the share of the beam that hits, and runs to
    the record's end for the share that misses (two cuts per pulse).
    """
    n = slots.shape[0]
    echo_range = hit_echo_range_m(hits)
    weight = hits.weight * hits.reflectance / np.pi * np.cos(hits.incidence_rad) * hits.receiver_weight
    hit_share = np.bincount(hits.pulse_index, weights=hits.weight, minlength=n)
    mean_range = np.bincount(hits.pulse_index, weights=hits.weight * hits.range_m, minlength=n)
    mean_range = np.divide(mean_range, hit_share, out=np.full(n, np.inf), where=hit_share > 0)
    cuts = np.stack([mean_range, np.full(n, np.inf)], axis=1)
    shares = np.stack([hit_share, 1.0 - hit_share], axis=1)
    return PulseBatch(pulse_id=slots, return_pulse=hits.pulse_index, return_range_m=echo_range,
                      return_weight_per_sr=weight, column_cut_m=cuts, column_cut_weight=np.clip(shares, 0.0, 1.0),
                      background_w=np.zeros(n))


def georeference(setup: PassSetup, ranging, hits: Hits, batch: PulseBatch, slots, times, est_o, est_d) -> PointRecords:
    """Points where the instrument and its navigation put them, with the truth attached.

    xyz = estimated beam origin + measured range x estimated beam direction. Class, object and incidence are
    those of the hit that made the echo (the strongest within a pulse length of the measured range).
    true_range_m is where the truth mesh lies along the point's own line of sight (its estimated beam), so
    range_error_m is the point's signed distance from the surface along that line; ranging error, merged
    echoes and navigation noise all show in it.
    """
    model = setup.model
    r = ranging.returns
    pulse = r.pulse
    n_hits = len(hits)
    offsets = np.searchsorted(hits.pulse_index, np.arange(batch.n_pulses + 1)).astype(np.int64)
    energy = target_factor(model.instrument, model.water, batch.return_range_m, batch.return_weight_per_sr)
    window_m = 0.5 * model.water.speed_m_s * model.instrument.transmitter.pulse_width_s
    j = match_returns_to_hits(pulse, r.range_m, offsets, batch.return_range_m, energy, window_m)
    j = np.where(j >= 0, j, 0) if n_hits else np.zeros(pulse.size, np.int64)
    origin, direction = est_o[pulse], est_d[pulse]
    xyz = origin + r.range_m[:, None] * direction

    scene = setup.scene
    ray, _, dist = scene.caster().first_hits((origin - scene.local_origin).astype(np.float32),
                                              direction.astype(np.float32))
    true_range = np.full(pulse.size, np.nan)
    true_range[ray] = dist
    unseen = np.isnan(true_range)
    true_range[unseen] = hits.range_m[j[unseen]] if n_hits else np.nan

    peak_power_w = r.amplitude_lsb / ChannelArrays.of(model).lsb_per_w[r.channel]
    scan_angle = np.degrees(setup.scanner.scan_angle_rad(times[pulse]))
    return PointRecords(
        gps_time_s=times[pulse], xyz=xyz, intensity=intensity_from_power(peak_power_w),
        return_number=ranging.return_number, number_of_returns=ranging.number_of_returns,
        classification=hits.label[j].astype(np.uint8), scan_angle_deg=scan_angle, channel=r.channel.astype(np.uint8),
        amplitude_lsb=r.amplitude_lsb, snr=r.snr, saturated=r.saturated, true_range_m=true_range,
        range_error_m=r.range_m - true_range, incidence_deg=np.degrees(hits.incidence_rad[j]),
        object_id=hits.object_id[j], pulse_index=slots[pulse])


class ErrorHistogram:
    """Streaming histogram of |range error| [m] for the summary's median and 95th percentile."""

    def __init__(self):
        self.counts = np.zeros(int(ERROR_MAX_M / ERROR_BIN_M) + 1, np.int64)

    def add(self, error_m: np.ndarray) -> None:
        e = np.abs(error_m[np.isfinite(error_m)])
        np.add.at(self.counts, np.minimum((e / ERROR_BIN_M).astype(np.int64), self.counts.size - 1), 1)

    def quantile(self, q: float) -> float | None:
        total = self.counts.sum()
        if total == 0:
            return None
        k = int(np.searchsorted(np.cumsum(self.counts), q * total))
        return (k + 0.5) * ERROR_BIN_M


def run_pass(config: SceneConfig, out_dir: str | Path | None = None, options: PassOptions = PassOptions(),
             scene=None) -> dict:
    """Simulate the scene's pass and write its outputs in ``out_dir`` (default: the scene's output dir).

    Returns the summary (also written as summary.json); ``wall_s`` and ``pulses_per_s`` time the pass
    itself (chunks, coverage tally and point/dropout writing), ``setup_s`` the scene, BVH and tables built
    before it. A scene with a seabed also gets its coverage (DESIGN.md section 7): the summary's ``coverage``,
    coverage_grid.npz and, when rendering, coverage_map.png. ``scene`` reuses an already built scene.
    """
    from tqdm import tqdm

    from . import io

    t_setup = time.perf_counter()
    setup = PassSetup.build(config, options, scene)
    coverage = CoverageAccumulator(setup.scene, options.coverage) if setup.scene.heightfield is not None else None
    setup_s = time.perf_counter() - t_setup
    out = Path(out_dir or config.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    pulses, channels, errors = 0, np.zeros(len(setup.model.instrument.channels) + 1, np.int64), ErrorHistogram()
    bar = tqdm(total=setup.expected_pulses(), unit="pulse", unit_scale=True, disable=not options.progress,
               desc=config.name)
    with io.LasWriter(out / "points.las", offset_m=setup.scene.local_origin) as las, \
            io.DropoutWriter(out / "dropouts.npz") as dropout_writer:
        for slots in setup.slot_chunks():
            chunk = setup.simulate_chunk(slots, footprint=coverage is not None)
            points = chunk.points
            las.write(points)
            dropout_writer.write(chunk.dropouts)
            if coverage is not None:
                coverage.add(slots, chunk.footprint, points, chunk.dropouts)
            pulses += slots.size
            channels += np.bincount(points.channel, minlength=channels.size)
            errors.add(points.range_error_m)
            bar.update(slots.size)
        n_points = las.point_count
        dropout_counts = dropout_writer.counts_by_cause()
    bar.close()
    wall_s = time.perf_counter() - started

    write_truth_and_trajectory(setup, out, options.write_scene)
    if options.waveforms:
        write_waveforms(setup, out / "waveforms.npz", options.waveforms)
    summary = {
        "scene": config.name,
        "water": setup.water_name,
        "seed": setup.seed,
        "fidelity": setup.fidelity,
        "pulses": pulses,
        "points": n_points,
        "dropouts": {cause: int(dropout_counts.get(cause, 0)) for cause in DROPOUT_CAUSES},
        "channels": {ch.name: int(channels[i + 1]) for i, ch in enumerate(setup.model.instrument.channels)},
        "wall_s": round(wall_s, 3),
        "setup_s": round(setup_s, 3),
        "pulses_per_s": round(pulses / wall_s, 1) if wall_s > 0 else None,
        "range_error_m": {"median": errors.quantile(0.5), "p95": errors.quantile(0.95)},
        "settings": {
            "instrument": setup.model.instrument.name,
            "record_mode": setup.record_mode,
            "subrays": setup.pattern.count,
            "shadow_rays": setup.shadow_rays,
            "chunk_pulses": setup.chunk_slots,
            "max_pulses": setup.max_pulses,
            "scene_file": str(config.source_path) if config.source_path else None,
        },
    }
    if coverage is not None:
        summary["coverage"] = coverage.figures()
        io.write_coverage_grid_npz(out / "coverage_grid.npz", coverage.grid, coverage.cell_states(),
                                   coverage.cells.reaching, coverage.cells.valid)
    io.write_summary_json(out / "summary.json", summary)
    if options.render:
        render_pass(setup, out, options.render_size)
        if coverage is not None:
            render_coverage_map(setup, coverage, out / "coverage_map.png", summary)
    return summary


def write_truth_and_trajectory(setup: PassSetup, out: Path, write_scene: bool = True) -> None:
    """scene.ply (labelled truth meshes; unless ``write_scene`` is False) and trajectory.csv (true and
    estimated poses at 10 Hz)."""
    from . import io

    scene = setup.scene
    if write_scene:
        io.write_scene_ply(out / "scene.ply", scene.vertices, scene.faces, scene.face_label, scene.face_object)
    t0 = setup.first_slot / setup.scanner.pulse_rate_hz
    t1 = setup.end_slot / setup.scanner.pulse_rate_hz
    t = np.arange(t0, t1, 1.0 / TRAJECTORY_RATE_HZ)
    true, est = setup.trajectory.poses(t), setup.trajectory.poses(t, estimated=True)
    rpy = lambda p: np.degrees(np.c_[p.roll_rad, p.pitch_rad, p.yaw_rad])  # noqa: E731
    io.write_trajectory_csv(out / "trajectory.csv", t, true.position, rpy(true),
                            estimated_position_m=est.position, estimated_attitude=rpy(est))


def write_waveforms(setup: PassSetup, path: Path, count: int) -> None:
    """Full records of ``count`` pulses spread evenly over the pass (same noise as in the pass itself)."""
    from . import io

    slots = np.concatenate(list(setup.slot_chunks()))
    pick = slots[np.unique(np.linspace(0, slots.size - 1, min(count, slots.size)).astype(np.int64))]
    records = setup.simulate_chunk(pick, record_mode="full").records
    time_ns = records.reference_times_s(setup.model) * 1e9  # full mode: the reference spans the record
    channels = {"ch0": records.reference}
    channels.update({ch.name: records.codes[:, i, :] for i, ch in enumerate(setup.model.instrument.channels)})
    io.write_waveforms_npz(path, pick, time_ns, channels)


def render_pass(setup: PassSetup, out: Path, window_size=(1600, 1000), max_points: int = 1_500_000) -> None:
    """render.png: the point cloud coloured by class over the faded truth mesh (decimated read-back)."""
    import laspy

    from . import viz

    with laspy.open(out / "points.las") as reader:
        stride = max(1, math.ceil(reader.header.point_count / max_points))
        xyz, cls = [], []
        for chunk in reader.chunk_iterator(1_000_000):
            xyz.append(np.c_[chunk.x, chunk.y, chunk.z][::stride])
            cls.append(np.asarray(chunk.classification)[::stride])
    xyz = np.concatenate(xyz) if xyz else np.zeros((0, 3))
    cls = np.concatenate(cls) if cls else np.zeros(0, np.uint8)
    scene = setup.scene
    viz.render_point_cloud(out / "render.png", xyz, cls, truth_vertices=scene.vertices, truth_faces=scene.faces,
                           title=f"{pass_label(setup)}: {xyz.shape[0]:,} points ({setup.fidelity})",
                           window_size=window_size)


def pass_label(setup: PassSetup) -> str:
    """'scene, water, instrument[, altitude]' for picture titles."""
    altitude = setup.config.platform.altitude_m
    return (f"{setup.config.name}, {setup.water_name}, {setup.model.instrument.name}"
            + (f", {altitude:g} m altitude" if altitude is not None else ""))


def render_coverage_map(setup: PassSetup, coverage: CoverageAccumulator, path: Path, summary: dict) -> None:
    """coverage_map.png: plan cells covered or missed by cause, cables drawn along, objects marked."""
    from . import viz
    from .coverage import BACKGROUND_KINDS, GAP_CAUSES

    scene = setup.scene
    lines = [(o.name, o.centreline[:, :2]) for o in scene.objects if o.centreline is not None]
    markers = []
    for o in scene.objects:
        if o.kind not in BACKGROUND_KINDS and o.centreline is None:
            corners = np.unique(scene.faces[o.face_start:o.face_stop].ravel())
            markers.append((o.name, scene.vertices[corners, :2].mean(axis=0)))
    figures = summary["coverage"]
    fraction = figures["covered_fraction"]
    title = (f"{pass_label(setup)}\ncovered {fraction:.1%} of {figures['reached_area_m2']:.0f} m² reached"
             if fraction is not None else f"{pass_label(setup)}\nthe scan reaches no seabed cell")
    viz.plot_coverage_map(path, coverage.cell_states(), coverage.grid.extent_m, GAP_CAUSES, lines=lines,
                          markers=markers, title=title)
