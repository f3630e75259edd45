"""Set-up checks: what a pass refuses before it runs (:class:`ConfigError` naming the key) or warns about
(:class:`SetupWarning` naming it), from the pass's estimated size to the built track against the water surface,
the seabed and the objects. ``docs/errors.md`` lists them. :func:`build_trajectory` builds a scene's trajectory
after these checks.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from scanner_sim.config.errors import ConfigError, SetupWarning, shown
from scanner_sim.motion.trajectory import PATH_STEP_M, Trajectory, trajectory_of


def build_trajectory(config, scene=None) -> Trajectory:
    """The :class:`Trajectory` of a :class:`scanner_sim.config.SceneConfig` over its built ``scene``, after
    the set-up checks: the pass's size is estimated before anything pass-sized is allocated
    (:func:`check_pass_budget`), and the built track is checked against the water surface, the seabed and the
    objects (:func:`check_track`). Raises :class:`ConfigError` naming the key; warns (:class:`SetupWarning`)
    about set-ups that run but likely not as meant."""
    check_pass_budget(config)
    trajectory = trajectory_of(config, scene)
    check_track(config, scene, trajectory)
    return trajectory


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
#: Share of the memory available when the pass is set up that it may plan to use.
MEMORY_SHARE = 0.8
#: Most pulses one pass may fire: about 100 GB of points and dropouts and a day of simulation. A longer
#: survey runs as several passes (survey.start_s, survey.duration_s).
MAX_PASS_PULSES = 1_000_000_000
#: Most legs a track may have: a point's LAS point_source_id numbers its leg in 16 bits.
MAX_LEGS = 65_535
#: Faster than survey vehicles go [m/s]; a faster speed is likely in km/h or knots (warned about).
MAX_PLAUSIBLE_SPEED_M_S = 10.0
#: Two-way attenuation exponent 2 k r beyond which no echo can return (e^-40 = 4e-18 of the light).
MAX_ATTENUATION_EXPONENT = 40.0
#: Largest number of track samples tested against one object's mesh.
MAX_CONTAINS_SAMPLES = 20_000


def available_memory_bytes() -> int | None:
    """Memory a new allocation can take [bytes]: ``MemAvailable`` of /proc/meminfo, less under a cgroup (v2
    or v1) limit; None where neither is known."""
    found = []
    try:
        with open("/proc/meminfo") as fh:
            found += [int(line.split()[1]) * 1024 for line in fh if line.startswith("MemAvailable:")]
    except (OSError, ValueError, IndexError):
        pass
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_file) as lf, open(usage_file) as uf:
                limit, usage = int(lf.read().split()[0]), int(uf.read().split()[0])
        except (OSError, ValueError, IndexError):  # absent, or "max" (no limit)
            continue
        if limit < 1 << 60:
            found.append(max(0, limit - usage))
    return min(found) if found else None


def track_length_m(platform) -> tuple[float, int]:
    """(length [m], legs) of a platform's track in plan, by arithmetic on the scene keys (nothing allocated)."""
    if platform.mode == "static":
        return 0.0, 1
    if platform.mode == "lawnmower":
        lm = platform.lawnmower
        n_lines = math.floor(lm.size_m[1] / lm.line_spacing_m + 1e-9) + 1
        return n_lines * lm.size_m[0] + (n_lines - 1) * lm.line_spacing_m, 2 * n_lines - 1
    seg = np.linalg.norm(np.diff(np.asarray(platform.waypoints_m, float)[:, :2], axis=0), axis=1)
    return float(seg.sum()), int(np.count_nonzero(seg > 1e-9))


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
    length_m, _ = track_length_m(p)
    rate = sc.pulse_rate_hz or config.instrument_model().transmitter.repetition_rate_hz
    active = sc.sector_deg / 360.0 if sc.mode == "continuous" else 1.0
    if p.mode == "static":
        pass_s = sv.duration_s if sv.duration_s is not None else sv.max_pulses / rate
        track_s = sv.start_s + pass_s
    else:
        track_s = length_m / p.speed_m_s
        pass_s = sv.duration_s if sv.duration_s is not None else track_s
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
    if config.seabed is not None:
        cells = math.prod(math.ceil(s / COVERAGE_CELL_M) for s in config.seabed.size_m)
        memory["seabed.size_m"] = (cells * COVERAGE_BYTES_PER_CELL, f"coverage over {cells:,} cells")
    return PassEstimate(track_s, pass_s, time_key, rate, active, pulses,
                        {k: (int(b), what) for k, (b, what) in memory.items()})


def _value(config, key: str) -> str:
    """The value of a dotted scene key, shortened for a message."""
    node = config
    for name in key.split("."):
        node = getattr(node, name)
    if hasattr(node, "model_dump"):
        node = node.model_dump()

    def lists(v):
        return [lists(x) for x in v] if isinstance(v, (tuple, list)) else v

    return shown(lists(node))


def _gb(n_bytes: float) -> str:
    return f"{n_bytes / 1e9:,.1f} GB" if n_bytes >= 1e8 else f"{n_bytes / 1e6:,.0f} MB"


def check_pass_budget(config, available_bytes: int | None = None) -> PassEstimate:
    """Refuse, before anything pass-sized is allocated, a pass that fires no pulse, more than
    :data:`MAX_PASS_PULSES`, has more than :data:`MAX_LEGS` legs, or would need more than :data:`MEMORY_SHARE`
    of the available memory (``available_bytes``, default :func:`available_memory_bytes`). The
    :class:`ConfigError` names the key that drives the figure. Returns the estimate."""
    est = estimate_pass(config)
    p, sv = config.platform, config.survey
    _, legs = track_length_m(p)
    if legs > MAX_LEGS:
        key = "platform.lawnmower.line_spacing_m" if p.mode == "lawnmower" else "platform.waypoints_m"
        raise ConfigError(f"{key} = {_value(config, key)}: gives a track of {legs:,} legs, more than the "
                          f"{MAX_LEGS:,} a LAS point_source_id can number; use wider lines or fewer waypoints")
    if p.mode != "static" and sv.start_s >= est.track_s:
        raise ConfigError(f"survey.start_s = {sv.start_s!r}: at or after the end of the track ({est.track_s:,.1f} s "
                          f"long at {p.speed_m_s:g} m/s); the pass would fire no pulse")
    if est.pulses < 1:
        raise ConfigError(f"{est.time_key} = {_value(config, est.time_key)}: the pass fires no pulse ({est.pass_s:.3g} s "
                          f"at {est.pulse_rate_hz:g} Hz, {est.active_fraction:.0%} of the slots firing); make it longer")
    if est.pulses > MAX_PASS_PULSES:
        raise ConfigError(f"{est.time_key} = {_value(config, est.time_key)}: the pass would fire {est.pulses:,} pulses "
                          f"({est.pass_s:,.0f} s at {est.pulse_rate_hz:g} Hz), more than the {MAX_PASS_PULSES:,} one "
                          "pass may; simulate part of it with survey.duration_s or survey.max_pulses (speeds are m/s)")
    available = available_memory_bytes() if available_bytes is None else available_bytes
    if available is not None and est.memory_bytes > MEMORY_SHARE * available:
        key, (n_bytes, what) = max(est.memory.items(), key=lambda kv: kv[1][0])
        raise ConfigError(f"{key} = {_value(config, key)}: the pass would need about {_gb(est.memory_bytes)} of "
                          f"memory ({what}: {_gb(n_bytes)}), more than the {_gb(MEMORY_SHARE * available)} it may "
                          f"use ({MEMORY_SHARE:.0%} of the {_gb(available)} available)")
    return est


def _vertical_key(config) -> str:
    p = config.platform
    if p.mode == "static" and len(p.position_m) == 3:
        return "platform.position_m"
    return "platform.altitude_m" if p.altitude_m is not None else "platform.depth_m"


def _plan_key(config) -> str:
    return {"static": "platform.position_m", "lawnmower": "platform.lawnmower"}.get(config.platform.mode,
                                                                                   "platform.waypoints_m")


def _at(x, y, z=None) -> str:
    return f"x = {x:.1f}, y = {y:.1f}" + (f", z = {z:+.2f}" if z is not None else "") + " m"


def check_track(config, scene, trajectory: Trajectory) -> None:
    """Refuse a pass whose vehicle rises above the water surface (z > 0), goes under the seabed, passes
    through an object or a rock, or never passes over the seabed; warn (:class:`SetupWarning`) when part of
    the track lies off the seabed, the speed is implausible, the pass runs past the end of the track, or the
    seabed lies beyond where any echo returns. ``trajectory``'s precomputed path is tested (every PATH_STEP_M),
    over the part the pass runs."""
    p, sv = config.platform, config.survey
    est = estimate_pass(config)
    s, xyz = trajectory.path()
    if trajectory.static:
        xyz = xyz[:1]
    else:
        s0, s1 = sv.start_s * trajectory.speed_m_s, (sv.start_s + est.pass_s) * trajectory.speed_m_s
        xyz = xyz[(s >= s0 - PATH_STEP_M) & (s <= s1 + PATH_STEP_M)]
    vertical = _vertical_key(config)
    top = int(np.argmax(xyz[:, 2]))
    if xyz[top, 2] > 0.0:
        raise ConfigError(f"{vertical} = {_value(config, vertical)}: the vehicle rises above the water surface (z = 0 "
                          f"in scene files) to {_at(*xyz[top])}; altitude_m is metres above the seabed")
    hf = scene.heightfield if scene is not None else None
    if hf is not None:
        x0, x1, y0, y1 = hf.extent_m
        over = (xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1)
        plan = _plan_key(config)
        if not over.any():
            raise ConfigError(f"{plan} = {_value(config, plan)}: the track never passes over the seabed (x {x0:g} to "
                              f"{x1:g}, y {y0:g} to {y1:g} m)")
        if not over.all():
            warnings.warn(SetupWarning(f"{plan}: {1 - over.mean():.0%} of the track lies off the seabed (x {x0:g} to "
                                       f"{x1:g}, y {y0:g} to {y1:g} m); no bottom is seen there"), stacklevel=3)
        ground = hf.height(xyz[over, 0], xyz[over, 1])
        under = int(np.argmin(xyz[over, 2] - ground))
        if xyz[over][under, 2] < ground[under]:
            depth = ground[under] - xyz[over][under, 2]
            hint = (f" (the altitude follows the seabed smoothed over follow_length_m = {p.follow_length_m:g} m)"
                    if vertical == "platform.altitude_m" else "")
            raise ConfigError(f"{vertical} = {_value(config, vertical)}: the vehicle goes {depth:.2f} m under the "
                              f"seabed at {_at(*xyz[over][under])}{hint}")
        reach = float(np.median(xyz[over, 2] - ground)) * 2.0 * config.water_model().two_way_attenuation_per_m
        if reach > MAX_ATTENUATION_EXPONENT:
            warnings.warn(SetupWarning(
                f"{vertical} = {_value(config, vertical)}: the seabed lies about {np.median(xyz[over, 2] - ground):,.0f} m "
                f"below the vehicle, where the water leaves e^-{reach:.0f} of the light: expect no returns "
                "(lengths are in metres)"), stacklevel=3)
    _check_objects(config, scene, xyz)
    if not trajectory.static and p.speed_m_s > MAX_PLAUSIBLE_SPEED_M_S:
        warnings.warn(SetupWarning(f"platform.speed_m_s = {p.speed_m_s!r}: faster than survey vehicles go (about 0.5 "
                                   f"to 3 m/s, at most {MAX_PLAUSIBLE_SPEED_M_S:g}); speeds are in m/s, not km/h or "
                                   "knots"), stacklevel=3)
    past = sv.start_s + est.pass_s - est.track_s
    if not trajectory.static and past > 1e-6:
        key = "survey.duration_s" if sv.duration_s is not None else "survey.start_s"
        warnings.warn(SetupWarning(f"{key} = {_value(config, key)}: the pass runs {past:,.1f} s past the end of the "
                                   f"track ({est.track_s:,.1f} s long), where the vehicle holds its last pose"),
                      stacklevel=3)


def _check_objects(config, scene, xyz: np.ndarray) -> None:
    """Refuse a track that passes through a closed mesh: an object's, or a rock's."""
    import trimesh

    if scene is None:
        return
    first_object = len(scene.objects) - len(config.objects)  # the seabed and its rocks come first
    for obj in scene.objects:
        if obj.kind == "seabed" or obj.face_stop == obj.face_start:
            continue
        faces = scene.faces[obj.face_start:obj.face_stop]
        corners = scene.vertices[np.unique(faces)]
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        near = xyz[((xyz >= lo) & (xyz <= hi)).all(axis=1)]
        if not len(near):
            continue
        used, local = np.unique(faces, return_inverse=True)
        mesh = trimesh.Trimesh(scene.vertices[used] - scene.local_origin, local.reshape(-1, 3), process=False)
        if not mesh.is_watertight:  # an open surface (a panel) has no inside
            continue
        near = near[:: max(1, len(near) // MAX_CONTAINS_SAMPLES)]
        hit = mesh.contains(near - scene.local_origin)
        if hit.any():
            where = _at(*near[int(np.argmax(hit))])
            name = ("a rock (seabed.rocks)" if obj.kind == "rocks" else
                    f"objects[{obj.object_id - first_object}] ({obj.name!r})")
            plan, vertical = _plan_key(config), _vertical_key(config)
            raise ConfigError(f"{plan}: the vehicle passes through {name} at {where}; move the track or raise "
                              f"{vertical.split('.')[-1]}")
