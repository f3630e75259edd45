"""A pass sized from its scene alone, before anything pass-sized is allocated: its duration, pulses and memory
by arithmetic on the scene keys, and the refusals (:class:`ConfigError` naming the key that drives the figure)
of a pass that fires no pulse, too many pulses or legs, or more memory than the machine has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from muls.infra.memory import MEMORY_SHARE, available_memory_bytes, gb
from scanner_sim.config import SeabedConfig
from scanner_sim.config.errors import ConfigError, config_value
from scanner_sim.motion.track_checks import track_length_m, track_span_s
from scanner_sim.motion.trajectory import PATH_STEP_M
from scanner_sim.world.raster import seabed_plan_size_m

#: Bytes a chunk holds per pulse slot and sub-ray (rays, hits, echoes), and per pulse slot for its records by
#: record mode, with the chunks a pass keeps in flight (one per worker and one more): the growth of peak RSS of
#: cable_survey passes between 10,000- and 80,000-pulse chunks on 2 cores (fast, 7 sub-rays: 5.6 kB per pulse;
#: balanced, 19: 9.7 kB; reference, 91 with full records: 48 kB), fitted and rounded up.
CHUNK_BYTES_PER_SUBRAY = 350
CHUNK_BYTES_PER_PULSE = {"windowed": 3_500, "full": 18_000}
#: Bytes of what grows with the track or the pass: a sample of the path (every PATH_STEP_M: position,
#: heading, height, pitch and their filters), of the navigation-noise grid (six processes and their filter),
#: a row of the 10 Hz trajectory table (true and estimated poses), a pulse slot listed for waveform
#: sampling, and a coverage cell (0.25 m, the default) of the seabed.
PATH_BYTES_PER_SAMPLE = 200
NOISE_BYTES_PER_SAMPLE = 200
TRAJECTORY_TABLE_RATE_HZ = 10.0
TRAJECTORY_BYTES_PER_ROW = 600
WAVEFORM_BYTES_PER_PULSE = 8
COVERAGE_CELL_M = 0.25
COVERAGE_BYTES_PER_CELL = 100
#: Most pulses one pass may fire: about 100 GB of points and dropouts and a day of simulation. A longer
#: survey runs as several passes (survey.start_s, survey.duration_s).
MAX_PASS_PULSES = 1_000_000_000
#: Most legs a track may have: a point's LAS point_source_id numbers its leg in 16 bits.
MAX_LEGS = 65_535

@dataclass(frozen=True)
class PassEstimate:
    """A pass sized from its scene alone: track and pass length [s] and the key that sets the pass length,
    pulse rate [Hz] and the share of slots that fire, pulses, and memory [bytes] by the scene key that drives
    each part (key -> (bytes, what))."""

    track_s: float
    pass_s: float
    time_key: str
    pulse_rate_hz: float
    active_fraction: float
    pulses: int
    memory: dict

    @property
    def memory_bytes(self) -> int:
        return sum(b for b, _ in self.memory.values())


def estimate_pass(config) -> PassEstimate:
    """Duration, pulses and memory of the scene's pass, by arithmetic on its keys (before allocating)."""
    p, sv, sc = config.platform, config.survey, config.scanner
    length_m, _ = track_length_m(p, config.seabed)
    rate = sc.pulse_rate_hz or config.instrument_model().transmitter.repetition_rate_hz
    active = sc.sector_deg / 360.0 if sc.mode == "continuous" else 1.0
    if p.mode == "static":
        pass_s = sv.duration_s if sv.duration_s is not None else sv.max_pulses / rate
        track_s = sv.start_s + pass_s
    else:
        track_s, pass_s = track_span_s(config)
    slots = pass_s * rate
    pulses = math.floor(min(slots * active, float(sv.max_pulses or math.inf)))
    level = sv.level
    time_key = "survey.duration_s" if sv.duration_s is not None else "platform.speed_m_s"
    track_key = "platform.lawnmower" if p.mode == "lawnmower" else "platform.waypoints_m"
    memory = {
        "survey.chunk_pulses": (sv.chunk_pulses * (level.subrays * CHUNK_BYTES_PER_SUBRAY
                                                   + CHUNK_BYTES_PER_PULSE.get(level.record_mode, 18_000)),
                                f"chunks of {sv.chunk_pulses:,} pulses x {level.subrays} sub-rays"),
        track_key: ((length_m / PATH_STEP_M + 2) * PATH_BYTES_PER_SAMPLE, f"a path {length_m:,.0f} m long"),
        time_key: (pass_s * TRAJECTORY_TABLE_RATE_HZ * TRAJECTORY_BYTES_PER_ROW,
                   f"the trajectory of a {pass_s:,.0f} s pass at {TRAJECTORY_TABLE_RATE_HZ:g} Hz"),
    }
    noise = p.navigation_noise
    if any((noise.position_sigma_m, noise.depth_sigma_m, noise.attitude_sigma_deg, noise.heading_sigma_deg)):
        memory["platform.navigation_noise.rate_hz"] = (track_s * noise.rate_hz * NOISE_BYTES_PER_SAMPLE,
                                                       f"navigation noise over {track_s:,.0f} s")
    if config.output.waveform_every_n_pulses:
        memory["output.waveform_every_n_pulses"] = (min(slots, pulses) * WAVEFORM_BYTES_PER_PULSE,
                                                    f"the list of {pulses:,} pulses to sample")
    size = seabed_plan_size_m(config)  # a raster's: the window the survey reads
    if size is not None:
        cells = math.prod(math.ceil(s / COVERAGE_CELL_M) for s in size)
        key = "seabed.size_m" if isinstance(config.seabed, SeabedConfig) else "seabed.raster"
        memory[key] = (cells * COVERAGE_BYTES_PER_CELL, f"coverage over {cells:,} cells")
    return PassEstimate(track_s, pass_s, time_key, rate, active, pulses,
                        {k: (int(b), what) for k, (b, what) in memory.items()})


def check_pass_budget(config, available_bytes: int | None = None) -> PassEstimate:
    """Refuse, before anything pass-sized is allocated, a pass that fires no pulse, more than
    :data:`MAX_PASS_PULSES`, has more than :data:`MAX_LEGS` legs, or would need more than :data:`MEMORY_SHARE`
    of the available memory (``available_bytes``, default :func:`available_memory_bytes`). The
    :class:`ConfigError` names the key that drives the figure. Returns the estimate."""
    est = estimate_pass(config)
    p, sv = config.platform, config.survey
    _, legs = track_length_m(p, config.seabed)
    if legs > MAX_LEGS:
        key = "platform.lawnmower.line_spacing_m" if p.mode == "lawnmower" else "platform.waypoints_m"
        raise ConfigError(f"{key} = {config_value(config, key)}: gives a track of {legs:,} legs, more than the "
                          f"{MAX_LEGS:,} a LAS point_source_id can number; use wider lines or fewer waypoints")
    if p.mode != "static" and sv.start_s >= est.track_s:
        raise ConfigError(f"survey.start_s = {sv.start_s!r}: at or after the end of the track ({est.track_s:,.1f} s "
                          f"long at {p.speed_m_s:g} m/s); the pass would fire no pulse")
    if est.pulses < 1:
        raise ConfigError(f"{est.time_key} = {config_value(config, est.time_key)}: the pass fires no pulse ({est.pass_s:.3g} s "
                          f"at {est.pulse_rate_hz:g} Hz, {est.active_fraction:.0%} of the slots firing); make it longer")
    if est.pulses > MAX_PASS_PULSES:
        raise ConfigError(f"{est.time_key} = {config_value(config, est.time_key)}: the pass would fire {est.pulses:,} pulses "
                          f"({est.pass_s:,.0f} s at {est.pulse_rate_hz:g} Hz), more than the {MAX_PASS_PULSES:,} one "
                          "pass may; simulate part of it with survey.duration_s or survey.max_pulses (speeds are m/s)")
    available = available_memory_bytes() if available_bytes is None else available_bytes
    if available is not None and est.memory_bytes > MEMORY_SHARE * available:
        key, (n_bytes, what) = max(est.memory.items(), key=lambda kv: kv[1][0])
        raise ConfigError(f"{key} = {config_value(config, key)}: the pass would need about {gb(est.memory_bytes)} of "
                          f"memory ({what}: {gb(n_bytes)}), more than the {gb(MEMORY_SHARE * available)} it may "
                          f"use ({MEMORY_SHARE:.0%} of the {gb(available)} available)")
    return est
