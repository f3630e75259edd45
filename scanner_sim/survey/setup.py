"""What a pass builds once, and its stages chosen once, the way pvlib's ModelChain picks its models: the scene
and its ray caster, the trajectory and the scanner, the instrument in its water, and, from the fidelity level, the
ray stage, the hand-off and the physics. A chunk goes through them in :mod:`scanner_sim.survey.chunk`; the chunk
loop (:mod:`scanner_sim.survey.pipeline`) only calls that.

:class:`PassPlan` is what the scene and the options decide before anything is built (the level, whether coverage
is measured, the files a pass writes): the pass and the campaign's completeness check read the same plan.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from muls.infra.runtime import configure_process
from muls.optics.optical_model import OpticalModel
from scanner_sim.config import SceneConfig
from scanner_sim.config.unit_slips import warn_unit_slips
from scanner_sim.fidelity import FidelityLevel
from scanner_sim.io.rosbag import ROSBAG_NAME, bag_files
from scanner_sim.metrics.coverage import CoverageSettings
from scanner_sim.motion.scanner import Scanner
from scanner_sim.motion.track_checks import build_trajectory
from scanner_sim.motion.trajectory import Trajectory
from scanner_sim.rays.auto import AutoCast
from scanner_sim.rays.beams import BeamPattern, beam_pattern
from scanner_sim.rays.cast import BeamCast, CastScene
from scanner_sim.rays.tiles import TiledCast, TiledTarget
from scanner_sim.survey.chunk import CastChunk, Chunk, Physics, cast_chunk, simulate_chunk
from scanner_sim.survey.gate import echo_span, rule_gate, warn_if_shut_out
from scanner_sim.survey.gis_products import gis_files
from scanner_sim.survey.handoff import Handoff
from scanner_sim.survey.pass_sample import spread_stretches
from scanner_sim.survey.ranging_precision import panel_ranges_m
from scanner_sim.survey.setup_cache import cached_ranging_precision, cached_scene
from scanner_sim.survey.sizing import check_pass_budget
from scanner_sim.survey.uncertainty import NavigationSigmas, TpuModel
from scanner_sim.world.scene import Scene
from scanner_sim.world.site import SiteScene


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

    def __post_init__(self):
        """The options' types, each refused by name (TypeError); the values of the scene keys they override are
        checked with the scene's (ConfigError naming ``survey.max_pulses`` and so on)."""
        def integer(value) -> bool:
            return isinstance(value, (int, np.integer)) and not isinstance(value, bool)

        for name in ("water", "fidelity"):
            if not isinstance(getattr(self, name), (str, type(None))):
                raise _type_error(f"PassOptions.{name}", "a name (str) or None", getattr(self, name))
        for name in ("seed", "max_pulses", "chunk_pulses"):
            if not (getattr(self, name) is None or integer(getattr(self, name))):
                raise _type_error(f"PassOptions.{name}", "an integer or None", getattr(self, name))
        if not integer(self.waveforms):
            raise _type_error("PassOptions.waveforms", "an integer", self.waveforms)
        if self.waveforms < 0:
            raise ValueError(f"PassOptions.waveforms = {self.waveforms!r}: must be >= 0")
        for name in ("progress", "render", "write_scene"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise _type_error(f"PassOptions.{name}", "True or False", getattr(self, name))
        size = self.render_size
        if not (isinstance(size, (tuple, list)) and len(size) == 2 and all(integer(n) for n in size)):
            raise _type_error("PassOptions.render_size", "a pair of integers (width, height) [px]", size)
        if min(size) < 1:
            raise ValueError(f"PassOptions.render_size = {tuple(size)!r}: must be >= 1 px each")
        if not isinstance(self.coverage, CoverageSettings):
            raise _type_error("PassOptions.coverage", "a CoverageSettings", self.coverage)

    def scene_overrides(self) -> dict[str, Any]:
        """The scene keys these options set, by dotted name."""
        keys = {"water": self.water, "survey.seed": self.seed, "survey.fidelity": self.fidelity,
                "survey.max_pulses": self.max_pulses, "survey.chunk_pulses": self.chunk_pulses}
        return {k: v for k, v in keys.items() if v is not None}


def _type_error(parameter: str, allowed: str, value) -> TypeError:
    """A one-line TypeError naming the parameter, what it takes and what it was given."""
    shown = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
    return TypeError(f"{parameter} must be {allowed}, not {type(value).__name__} {shown}")


def check_pass_arguments(config, options, scene) -> None:
    """The arguments of a pass's entry points (:func:`~scanner_sim.survey.pipeline.run_pass`, ``simulate_pass``,
    :meth:`PassSetup.build`): a TypeError naming the parameter, instead of an AttributeError deep inside."""
    if not isinstance(config, SceneConfig):
        raise _type_error("config", "a SceneConfig (scanner_sim.load_scene(name_or_path) gives one)", config)
    if not isinstance(options, PassOptions):
        raise _type_error("options", "a PassOptions (scanner_sim.PassOptions(max_pulses=...))", options)
    if scene is not None and not isinstance(scene, (Scene, SiteScene)):
        raise _type_error("scene", "a Scene built from this config (scanner_sim.build_scene(config)) or None", scene)


@dataclass(frozen=True)
class PassPlan:
    """What a pass does, decided from its scene (every override applied) and options before anything is built.

    level: the fidelity level (the scene's ``survey.fidelity`` with its ``subrays`` and ``shadow_rays`` overrides,
    or one given); measures_coverage: the pass tallies coverage (the scene has a seabed); files: the names of the
    files a complete pass writes into its folder, summary.json last, per-leg point clouds and trajectories aside
    (how many legs a pass reaches is known only when it has run)."""

    level: FidelityLevel
    measures_coverage: bool
    files: tuple[str, ...]

    @classmethod
    def of(cls, config: SceneConfig, options: PassOptions = PassOptions(), level: FidelityLevel | None = None
           ) -> PassPlan:
        """The plan of ``config`` with ``options`` applied (or already applied: they are idempotent)."""
        config = config.with_overrides(options.scene_overrides())
        output, coverage = config.output, config.has_seabed
        clouds = [s for s, on in ((".las", output.las), (".laz", output.laz)) if on]
        files = [] if output.split_legs else [f"points{s}" for s in clouds]
        files += ["points.copc.laz"] if output.copc else []
        files += ["dropouts.npz"]
        files += ["coverage_grid.npz"] if coverage else []
        files += ["trajectory.csv"] if output.trajectory_csv and not output.split_legs else []
        files += ["scene.ply"] if options.write_scene else []
        files += ["waveforms.npz"] if options.waveforms or output.waveform_every_n_pulses else []
        files += ["render.png"] if options.render and clouds else []
        files += ["coverage_map.png", "s44_map.png"] if options.render and coverage else []
        files += gis_files(coverage) if config.crs is not None else []
        if output.rosbag is not None and output.rosbag.dir is None:  # a bag elsewhere is no file of the folder
            files += bag_files(ROSBAG_NAME, output.rosbag.storage)
        return cls(level or config.survey.level, coverage, (*files, "summary.json"))


def ray_stage(level: FidelityLevel, target: CastScene, pattern: BeamPattern, geometry) -> BeamCast:
    """The ray stage of ``level``: the ``auto`` level's (:class:`~scanner_sim.rays.auto.AutoCast`) or the beam cast
    every other level shares (:class:`~scanner_sim.rays.cast.BeamCast`)."""
    if isinstance(target, TiledTarget):
        return TiledCast(target, pattern, geometry, level.shadow_rays, level.adaptive)
    return (AutoCast if level.adaptive else BeamCast)(target, pattern, geometry, level.shadow_rays)


class Stages(NamedTuple):
    """What a fidelity level chooses for a pass, once: the optical model, the sub-ray pattern, and the stages the
    chunk loop calls (``rays``: hits of a chunk's pulses; ``handoff``: their muls input; ``physics``: records and
    ranging)."""

    model: OpticalModel
    pattern: BeamPattern
    rays: BeamCast
    handoff: Handoff
    physics: Physics


def _stages(config: SceneConfig, target: CastScene, model: OpticalModel, level: FidelityLevel) -> Stages:
    """The stages of a pass at ``level``; ``model`` is rebuilt when the level models multiple scattering
    otherwise."""
    if model.multiple_scattering != level.multiple_scattering:
        model = OpticalModel.build(model.instrument, model.water, level.multiple_scattering)
    pattern = beam_pattern(level.subrays, config.survey.beam_profile)
    return Stages(model, pattern, ray_stage(level, target, pattern, model.instrument.geometry),
                  Handoff(model, config.water.background_radiance_w_m2_sr_nm, level.column_cut),
                  Physics(model, config.survey.seed, level.record_mode, level.deciding_only))


def gated(config: SceneConfig, water, span) -> SceneConfig:
    """``config`` with its far channel's gate set by the operator's rule where the scene gives none
    (:mod:`scanner_sim.survey.gate`), and a warning where the scene's own gate shuts out the survey's echoes
    (``span``: :func:`~scanner_sim.survey.gate.echo_span` of the pass); as it is when the instrument has no gated
    channel."""
    instrument = config.instrument.to_instrument(water)
    far = [ch for ch in instrument.channels if ch.gated]
    if not far:
        return config
    duration_s = instrument.pulse.duration_s
    if config.instrument.gate_delay_ns is not None:
        warn_if_shut_out(span, far[0].gate_delay_s, far[0].gate_delay_s + far[0].gate_width_s, duration_s)
        return config
    gate = rule_gate(span, duration_s)
    if gate is None:
        return config
    return config.with_overrides({"instrument.gate_delay_ns": round(gate[0] * 1e9, 3),
                                  "instrument.gate_width_ns": round(gate[1] * 1e9, 3)}, given=False)


def tpu_model(config: SceneConfig, model: OpticalModel, physics: Physics, span) -> TpuModel:
    """The pass's uncertainty model (:mod:`scanner_sim.survey.uncertainty`): its ranging precision measured through
    ``physics`` on panels at the ranges of its echoes (``span``: :func:`~scanner_sim.survey.gate.echo_span`; 5 m
    when no sampled beam meets anything), its navigation noise, its beam and its pulse's rms length in range."""
    ranges = panel_ranges_m(span.delays_s, model.water.speed_m_s) if span.delays_s.size else (5.0,)
    geometry = model.instrument.geometry
    return TpuModel(cached_ranging_precision(physics, model.instrument, ranges),
                    NavigationSigmas.of(config.platform.navigation_noise), geometry.beam_diameter_m,
                    geometry.beam_divergence_full_rad, 0.5 * model.water.speed_m_s * model.instrument.pulse.rms_width_s)


def checked_trajectory(config: SceneConfig, scene: Scene | None) -> Trajectory:
    """The trajectory of ``config`` over its built ``scene``, after the set-up checks: the pass's size, estimated
    before anything pass-sized is allocated (:func:`~scanner_sim.survey.sizing.check_pass_budget`), and the built
    track against the water surface, the seabed and the objects
    (:func:`~scanner_sim.motion.track_checks.build_trajectory`); values likely in another unit are warned about
    (:func:`~scanner_sim.config.unit_slips.warn_unit_slips`)."""
    check_pass_budget(config)
    warn_unit_slips(config)
    return build_trajectory(config, scene)


@dataclass(frozen=True)
class PassSetup:
    """What a pass builds once, and its stages: the scene (every override applied) and what the rays are cast
    into, the trajectory, the scanner, the instrument in its water, the plan, and the stages the chunk loop calls
    (``rays``: hits of a chunk's pulses; ``handoff``: their muls input; ``physics``: records and ranging); the
    pass's slot range, the water's name, and the scene as given (``given``: every override applied, before the pass
    derived its gate; what the pass's inputs fingerprint covers)."""

    config: SceneConfig
    plan: PassPlan
    target: CastScene
    trajectory: Trajectory
    scanner: Scanner
    model: OpticalModel
    pattern: BeamPattern
    rays: BeamCast
    handoff: Handoff
    physics: Physics
    first_slot: int
    end_slot: int
    water_name: str
    given: SceneConfig
    tpu: TpuModel
    #: [s] spent measuring the TPU's ranging table at set-up: on a fresh machine this is where the physics kernels
    #: compile first, so a pass reports it in ``compile_s`` rather than ``setup_s``.
    ranging_s: float = 0.0
    #: (first slot, end slot) of each stretch of the pass that is simulated instead of its whole slot range
    #: (:meth:`spread_sample`), or empty: the slot range, at most ``max_pulses`` pulses.
    stretches: tuple[tuple[int, int], ...] = ()

    @classmethod
    def build(cls, config: SceneConfig, options: PassOptions = PassOptions(), scene: Scene | None = None,
              level: FidelityLevel | None = None) -> PassSetup:
        """``scene``: the already built :class:`Scene` of ``config`` to reuse, if any; ``level``: run at this
        fidelity level instead of the scene's (the trade-off study's knobs)."""
        check_pass_arguments(config, options, scene)
        configure_process()
        config = given = config.with_overrides(options.scene_overrides())
        survey = config.survey
        water = config.water_model()
        scene = cached_scene(config) if scene is None else scene
        # The Embree BVH and the seabed's proof grid: set-up, not part of the pass (a site's: per window, as it goes).
        target = TiledTarget(scene) if isinstance(scene, SiteScene) else CastScene.of(scene)
        trajectory = checked_trajectory(config, scene)
        scanner = Scanner.from_config(config.scanner, config.instrument.to_instrument(water))
        rate = scanner.pulse_rate_hz
        duration = survey.duration_s if survey.duration_s is not None else trajectory.duration_s
        first_slot, end_slot = math.ceil(survey.start_s * rate - 1e-9), math.ceil((survey.start_s + duration) * rate - 1e-9)
        span = echo_span(target, trajectory, scanner, water.speed_m_s, first_slot, end_slot)
        config = gated(config, water, span)
        plan = PassPlan.of(config, options, level)
        model = OpticalModel.build(config.instrument.to_instrument(water), water, plan.level.multiple_scattering)
        stages = _stages(config, target, model, plan.level)
        started = time.perf_counter()
        tpu = tpu_model(config, stages.model, stages.physics, span)
        return cls(config, plan, target, trajectory, scanner, **stages._asdict(), first_slot=first_slot,
                   end_slot=end_slot, water_name=config.water.preset or water.name, given=given, tpu=tpu,
                   ranging_s=time.perf_counter() - started)

    def at_level(self, level: FidelityLevel) -> PassSetup:
        """This pass at fidelity ``level``: its plan, sub-ray pattern and stages chosen again (the built scene,
        trajectory and tables kept), its ranging precision measured again through the new physics."""
        stages = _stages(self.config, self.target, self.model, level)
        tpu = dataclasses.replace(self.tpu, ranging=cached_ranging_precision(stages.physics, stages.model.instrument,
                                                                              self.tpu.ranging.ranges_m))
        return dataclasses.replace(self, plan=dataclasses.replace(self.plan, level=level), **stages._asdict(), tpu=tpu)

    def with_seeds(self, survey_seed: int, navigation_seed: int) -> PassSetup:
        """This pass with ``survey.seed`` and ``platform.navigation_noise.seed`` set, without building the BVH
        again: the trajectory (its navigation noise) is built again and the physics draws with the new seed, so the
        points are those :meth:`build` gives for the scene with these seeds. The gate follows the true poses, which
        no seed moves, and is kept; so is the TPU model, its ranging table measured once through this pass's
        physics (a table of the instrument in its water, which a seed changes only by the sampling noise of its
        8,960 shots; measuring it again would cost a member about 20 times its 300 pulses)."""
        seeds = {"survey.seed": survey_seed, "platform.navigation_noise.seed": navigation_seed}
        config, given = self.config.with_overrides(seeds), self.given.with_overrides(seeds)
        return dataclasses.replace(self, config=config, given=given, trajectory=checked_trajectory(config, self.scene),
                                   physics=dataclasses.replace(self.physics, seed=config.survey.seed))

    @property
    def level(self) -> FidelityLevel:
        return self.plan.level

    @property
    def scene(self) -> Scene:
        return self.target.scene

    @property
    def seed(self) -> int:
        return self.config.survey.seed

    @property
    def max_pulses(self) -> int | None:
        return self.config.survey.max_pulses

    @property
    def chunk_slots(self) -> int:
        """Pulse slots per chunk: those in which ``survey.chunk_pulses`` pulses fire (a sector scan fires a share of
        its slots, 90 deg of 360: a quarter), so that a chunk holds about that many pulses whatever the scan."""
        return max(1, round(self.config.survey.chunk_pulses / self.scanner.active_fraction))

    def expected_pulses(self) -> int:
        """The pulses the pass fires: its slots that fire (exactly, as :meth:`slot_chunks` yields them), at most
        ``max_pulses``, or those of its ``stretches``; the progress bar's total."""
        if self.stretches:
            return sum(self.scanner.fired_count(first, end) for first, end in self.stretches)
        n = self.scanner.fired_count(self.first_slot, self.end_slot)
        return min(n, self.max_pulses) if self.max_pulses else n

    def slot_chunks(self):
        """Yield (n,) int64 slot numbers of the fired pulses, ``chunk_slots`` slots at a time (about
        ``survey.chunk_pulses`` pulses): of the slot range, at most ``max_pulses`` pulses, or of each stretch of
        ``stretches`` in turn."""
        if not self.stretches:
            yield from self._fired_slots(self.first_slot, self.end_slot, self.max_pulses)
        for first, end in self.stretches:
            yield from self._fired_slots(first, end, None)

    def _fired_slots(self, first: int, end: int, max_pulses: int | None):
        rate, fired = self.scanner.pulse_rate_hz, 0
        for k0 in range(first, end, self.chunk_slots):
            k1 = min(end, k0 + self.chunk_slots)
            slots = self.scanner.pulse_slots(k0 / rate, k1 / rate)
            if max_pulses is not None:
                slots = slots[: max_pulses - fired]
            if slots.size:
                fired += slots.size
                yield slots
            if max_pulses is not None and fired >= max_pulses:
                return

    def spread_sample(self, pulses: int, stretches: int) -> PassSetup:
        """This pass cut to ``pulses`` of its pulses in ``stretches`` runs of consecutive pulses spread evenly over it
        (:func:`~scanner_sim.survey.pass_sample.spread_stretches`); the whole pass when it fires no more."""
        n = self.expected_pulses()
        if pulses >= n:
            return self
        wanted = spread_stretches(n, pulses, stretches)
        ends = {i: None for first, size in wanted for i in (first, first + size - 1)}  # pulse index -> its slot
        seen = 0
        for slots in self.slot_chunks():
            for i in ends:
                if seen <= i < seen + slots.size:
                    ends[i] = int(slots[i - seen])
            seen += slots.size
        return dataclasses.replace(self, stretches=tuple((ends[first], ends[first + size - 1] + 1)
                                                         for first, size in wanted))

    def cast_chunk(self, slots: np.ndarray) -> CastChunk:
        """The ray stage of one chunk of pulse slots (n,) (:func:`~scanner_sim.survey.chunk.cast_chunk`)."""
        return cast_chunk(self, slots)

    def simulate_chunk(self, slots: np.ndarray, record_mode: str | None = None, every_channel: bool = False,
                       whole_records: bool = False) -> Chunk:
        """One chunk of pulse slots (n,) through the whole flow (:func:`~scanner_sim.survey.chunk.simulate_chunk`;
        ``record_mode``, ``every_channel``, ``whole_records``: as :class:`~scanner_sim.survey.chunk.Physics`)."""
        return simulate_chunk(self, slots, record_mode, every_channel, whole_records)
