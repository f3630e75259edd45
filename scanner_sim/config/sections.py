"""The scene file's sections besides the geometry: water, instrument, platform, scanner, survey, output.

Units are in the keys; angles in ``_deg`` stay degrees here and are converted where they are used.
"""

import math
from dataclasses import replace
from typing import Annotated, Any

from pydantic import BeforeValidator, model_validator

from muls import WATER_PRESETS, instrument_preset, water_preset
from muls.infra.errors import ParameterError
from muls.water.phase_family import phase_from_spec
from muls.water.properties import (
    ATTENUATION_MODELS,
    BACKSCATTER_MODELS,
    GROUP_INDEX_SEAWATER,
    MULTIPLE_SCATTERING,
    Water,
)
from scanner_sim.config.base import (
    Choice,
    Integer,
    NonNegative,
    Number,
    Points,
    Positive,
    Real,
    StrictModel,
    Vector,
)
from scanner_sim.config.errors import invalid
from scanner_sim.fidelity import FIDELITY_LEVELS, FidelityLevel

WaterPreset = Choice(*sorted(WATER_PRESETS))

#: Largest seed: numpy's generators and muls's noise keys take 0 .. 2**63 - 1 without wrapping.
MAX_SEED = 2**63 - 1
#: Sub-ray counts the beam's ring layout allows (:func:`scanner_sim.rays.beams.beam_pattern`): 1 + 3 N (N + 1).
SUBRAY_COUNTS = tuple(1 + 3 * n * (n + 1) for n in range(0, 9))  # 1, 7, 19, 37, 61, 91, 127, 169, 217
#: Energy profiles across the beam.
PROFILES = ("top_hat", "gaussian")
#: Deeper than any ocean (the Challenger Deep is about 10,935 m) [m]: a larger depth is a unit slip.
MAX_DEPTH_M = 11_000.0


def check_depth_m(value: float, key: str) -> None:
    """Reject a depth [m] deeper than any ocean (:data:`MAX_DEPTH_M`): it is in another unit."""
    if value > MAX_DEPTH_M:
        raise invalid(f"deeper than any ocean ({MAX_DEPTH_M:,.0f} m); depths are in metres", key=key, value=value)


class WaterConfig(StrictModel):
    """The water: a preset name, or its optical properties at 532 nm (absorption with exactly one of
    scattering and attenuation). ``water: turbid_harbor`` is short for ``water: {preset: turbid_harbor}``."""

    preset: WaterPreset | None = None
    """A muls water preset; takes only attenuation_model, backscatter_model and the background beside it."""
    absorption_per_m: NonNegative | None = None
    """Absorption coefficient a [1/m]."""
    scattering_per_m: NonNegative | None = None
    """Scattering coefficient b [1/m]."""
    attenuation_per_m: Positive | None = None
    """Beam attenuation c = a + b [1/m]."""
    group_index: Number(ge=1.0, le=2.0) | None = None
    """Group refractive index (speed of the pulse); default that of sea water."""
    beta_pi_per_m_sr: NonNegative | None = None
    """Measured volume scattering function at 180 degrees [1/(m sr)]."""
    attenuation_model: Choice(*ATTENUATION_MODELS) | None = None
    """Attenuation the echo sees (muls.water.properties)."""
    backscatter_model: Choice(*BACKSCATTER_MODELS) | None = None
    """Water-column backscatter model (muls.water.properties)."""
    background_radiance_w_m2_sr_nm: NonNegative = 0.0
    """Spectral radiance L_b of artificial light in the water [W/(m^2 sr nm)] (MULS Eqs. 8-10), allowed beside a
    preset; 0 (the default) is deep, dark water."""
    phase_function: str | None = None
    """The particles' phase function, allowed beside a preset: a name with optional parameters, e.g. ``petzold``
    (the default), ``fournier_forand:mu=3.37,n=1.066``, ``henyey_greenstein:g=0.9`` (muls.water.phase_family)."""

    @model_validator(mode="after")
    def _one_description(self):
        if self.phase_function is not None:
            try:
                phase_from_spec(self.phase_function)
            except ParameterError as exc:  # the reason without muls's own naming of the value
                reason = str(exc).split(": ", 1)[1] if str(exc).startswith("phase_function = ") else str(exc)
                raise invalid(reason, key="phase_function", value=self.phase_function) from None
        a, b, c = self.absorption_per_m, self.scattering_per_m, self.attenuation_per_m
        if self.preset is not None:
            if any(v is not None for v in (a, b, c, self.group_index, self.beta_pi_per_m_sr)):
                raise invalid("give a preset or optical properties, not both (a preset takes only "
                              "attenuation_model, backscatter_model and background_radiance_w_m2_sr_nm)")
        elif a is None or (b is None) == (c is None):
            raise invalid("give a preset name, or absorption_per_m with exactly one of scattering_per_m and "
                          "attenuation_per_m",
                          value={"absorption_per_m": a, "scattering_per_m": b, "attenuation_per_m": c})
        elif c is not None and a > c:
            raise invalid(f"must be <= attenuation_per_m ({c!r})", key="absorption_per_m", value=a)
        elif b is not None and a + b <= 0.0:
            raise invalid("absorption_per_m + scattering_per_m = 0: attenuation must be > 0")
        return self

    def to_water(self, name: str = "custom") -> Water:
        """The :class:`muls.water.properties.Water` this section describes."""
        if self.preset is not None:
            water = water_preset(self.preset)
        else:
            kw = {"group_index": self.group_index or GROUP_INDEX_SEAWATER,
                  "beta_pi_measured_per_m_sr": self.beta_pi_per_m_sr, "source": "scene file"}
            if self.attenuation_per_m is not None:
                water = Water.from_attenuation(name, self.attenuation_per_m, self.absorption_per_m, **kw)
            else:
                water = Water(name, self.absorption_per_m, self.scattering_per_m, **kw)
        return replace(water, attenuation_model=self.attenuation_model or water.attenuation_model,
                       backscatter_model=self.backscatter_model or water.backscatter_model,
                       phase_function=self.phase_function or water.phase_function)


def _preset_shorthand(value: Any) -> Any:
    return {"preset": value} if isinstance(value, str) else value


#: ``water`` as written: a section, or a preset's name alone (``water: turbid_harbor``).
WaterSection = Annotated[WaterConfig, BeforeValidator(_preset_shorthand, json_schema_input_type=WaterConfig | WaterPreset)]


class InstrumentConfig(StrictModel):
    """A muls instrument preset and overrides of its values (None keeps the preset's)."""

    preset: Choice("mul2023", "single_channel", "coaxial") = "mul2023"
    """The MUL prototype of the 2023 paper, one non-gated channel, or the MUL with coaxial optics."""
    gate_delay_ns: NonNegative | None = None
    """Opening of the gated channel(s) after the pulse [ns]; give gate_width_ns with it."""
    gate_width_ns: Positive | None = None
    """How long the gate stays open [ns]."""
    pulse_energy_j: Positive | None = None
    """Pulse energy [J]."""
    pulse_width_ns: Positive | None = None
    """Pulse duration (FWHM) [ns]."""
    beam_diameter_m: Positive | None = None
    """Beam diameter at the exit window [m]."""
    beam_divergence_full_rad: Number(ge=0.0, lt=math.pi) | None = None
    """Full beam divergence angle [rad]."""
    fov_full_rad: Number(gt=0.0, lt=math.pi) | None = None
    """Full receiver field-of-view angle [rad]."""
    receiver_offset_m: NonNegative | None = None
    """Transmitter-receiver offset d along the mirror shaft [m]."""
    receiver_area_m2: Positive | None = None
    """Receiver aperture area [m^2]."""

    @model_validator(mode="after")
    def _gate_pair(self):
        if (self.gate_delay_ns is None) != (self.gate_width_ns is None):
            raise invalid("give both gate_delay_ns and gate_width_ns, or neither")
        return self

    def to_instrument(self, water: Water | None = None):
        """The :class:`muls.instrument.description.Instrument` with the overrides applied."""
        inst = instrument_preset(self.preset, water)
        tx = {k: v for k, v in (("pulse_energy_j", self.pulse_energy_j), ("beam_diameter_m", self.beam_diameter_m),
                                ("beam_divergence_full_rad", self.beam_divergence_full_rad)) if v is not None}
        if self.pulse_width_ns is not None:
            tx["pulse_width_s"] = self.pulse_width_ns * 1e-9
        rx = {k: v for k, v in (("fov_full_rad", self.fov_full_rad), ("offset_m", self.receiver_offset_m),
                                ("area_m2", self.receiver_area_m2)) if v is not None}
        inst = replace(inst, transmitter=replace(inst.transmitter, **tx), receiver=replace(inst.receiver, **rx))
        if self.gate_delay_ns is not None:
            for ch in inst.channels:
                if ch.gated:
                    inst = inst.with_channel(ch.name, gate_delay_s=self.gate_delay_ns * 1e-9,
                                             gate_width_s=self.gate_width_ns * 1e-9)
        return inst


class LawnmowerConfig(StrictModel):
    """Survey lines over a rectangle."""

    center_m: Vector(2) = (0.0, 0.0)
    """Centre of the rectangle [x, y] [m]."""
    size_m: Vector(2, element=Positive) | None = None
    """Extent along the lines and across them [m]; null (over a raster seabed): the raster's valid extent."""
    heading_deg: Real = 0.0
    """Compass direction of the first line [deg]."""
    line_spacing_m: Positive = 4.0
    """Distance between lines [m]."""


class AttitudeConfig(StrictModel):
    """Attitude on top of the track: constant offsets and sinusoidal motion. Pitch nose-up and roll
    starboard-down are positive."""

    pitch_deg: Number(ge=-90.0, le=90.0) = 0.0
    roll_deg: Number(ge=-90.0, le=90.0) = 0.0
    pitch_amplitude_deg: Number(ge=0.0, le=45.0) = 0.0
    pitch_period_s: Positive = 8.0
    roll_amplitude_deg: Number(ge=0.0, le=45.0) = 0.0
    roll_period_s: Positive = 6.0
    follow_terrain_pitch: bool = True
    """Pitch with the smoothed altitude profile."""


class NavigationNoiseConfig(StrictModel):
    """Errors of the *estimated* pose: first-order Gauss-Markov processes with these standard deviations
    and correlation time, sampled at ``rate_hz`` and interpolated; seeded."""

    position_sigma_m: NonNegative = 0.0
    """East and north [m]."""
    depth_sigma_m: NonNegative = 0.0
    attitude_sigma_deg: NonNegative = 0.0
    """Roll and pitch [deg]."""
    heading_sigma_deg: NonNegative = 0.0
    correlation_time_s: Positive = 10.0
    rate_hz: Positive = 100.0
    """Rate of the noise grid [Hz]."""
    seed: Integer(ge=0, le=MAX_SEED) = 0


class PlatformConfig(StrictModel):
    """The vehicle: a trajectory mode, speed, vertical reference (altitude or depth), attitude and
    navigation noise."""

    mode: Choice("waypoints", "lawnmower", "static") = "waypoints"
    speed_m_s: Positive = 1.0
    waypoints_m: Points(2) | None = None
    """[x, y] points of the track (mode waypoints) [m]."""
    line_plan: str | None = None
    """Survey lines from a GeoJSON (lon/lat) or CSV (line, x, y or line, lon, lat) file, in place of waypoints_m;
    path relative to the scene file."""
    lawnmower: LawnmowerConfig | None = None
    """The pattern (mode lawnmower)."""
    position_m: Vector(2, 3) | None = None
    """Where a static platform stands: [x, y, z], or [x, y] with altitude_m or depth_m [m]."""
    heading_deg: Real = 0.0
    """Compass heading of a static platform [deg]."""
    altitude_m: Positive | None = None
    """Height above the smoothed seabed [m]; or depth_m, exactly one."""
    depth_m: NonNegative | None = None
    """Constant depth below the surface, z = -depth_m [m]."""
    follow_length_m: Positive = 1.5
    """Gaussian sigma of the terrain low-pass for altitude following [m]."""
    turn_length_m: NonNegative = 1.0
    """Corners are rounded over this length [m]."""
    attitude: AttitudeConfig = AttitudeConfig()
    navigation_noise: NavigationNoiseConfig = NavigationNoiseConfig()

    @model_validator(mode="after")
    def _mode_needs(self):
        if self.mode == "waypoints" and self.waypoints_m is None:
            raise invalid("missing; mode 'waypoints' needs a list of at least 2 [x, y] points", key="waypoints_m")
        if self.mode == "lawnmower" and self.lawnmower is None:
            raise invalid("missing; mode 'lawnmower' needs center_m, size_m, heading_deg, line_spacing_m",
                          key="lawnmower")
        if self.mode == "static" and self.position_m is None:
            raise invalid("missing; mode 'static' needs [x, y, z] or [x, y] with altitude_m or depth_m",
                          key="position_m")
        needs_vertical = not (self.mode == "static" and len(self.position_m) == 3)
        given = [k for k in ("altitude_m", "depth_m") if getattr(self, k) is not None]
        if needs_vertical and len(given) != 1:
            raise invalid("give exactly one of altitude_m (follow the seabed) and depth_m (constant depth), "
                          f"got {given or 'neither'}")
        if not needs_vertical and given:
            raise invalid("not allowed with a 3-D static position_m", key=given[0])
        if self.mode == "waypoints" and len(set(self.waypoints_m)) < 2:
            raise invalid("the points coincide; a track needs two distinct points (or mode 'static')",
                          key="waypoints_m", value=[list(p) for p in self.waypoints_m])
        if self.mode == "static" and len(self.position_m) == 3 and self.position_m[2] > 0.0:
            raise invalid(f"z = {self.position_m[2]:g} m is above the water surface (z = 0 in scene files); "
                          "give z <= 0", key="position_m", value=list(self.position_m))
        if self.depth_m is not None:
            check_depth_m(self.depth_m, "depth_m")
        return self


class ScannerConfig(StrictModel):
    """The RM3/RM4 mirror shaft: mode, rates, sector of scan angle from nadir, mounting on the vehicle."""

    mode: Choice("continuous", "oscillating", "static") = "continuous"
    scan_rate_hz: Positive = 10.0
    """Revolutions (continuous) or full back-and-forth periods (oscillating) per second [Hz]."""
    sector_deg: Number(gt=0.0, le=360.0) = 90.0
    """Active sector of scan angle, centred on center_deg [deg]."""
    center_deg: Number(ge=-180.0, le=180.0) = 0.0
    """Centre of the sector; 0 = nadir [deg]."""
    aim_deg: Number(ge=-180.0, le=180.0) = 0.0
    """Scan angle of every pulse in static mode [deg]."""
    oscillation: Choice("triangle", "sine") = "triangle"
    """Triangle (constant rate) or sine sweep."""
    pulse_rate_hz: Number(gt=0.0, le=1e7) | None = None
    """Laser pulse rate [Hz]; null = the instrument's repetition rate."""
    mounting: Choice("along_track", "across_track") = "along_track"
    """Shaft along the track (cross-track lines) or across it (fore-aft profile)."""
    mount_position_m: Vector(3) = (0.0, 0.0, 0.0)
    """Beam exit point in the platform frame (x forward, y left, z up) [m]."""

    @model_validator(mode="after")
    def _oscillating_sector(self):
        if self.mode == "oscillating" and self.sector_deg >= 360.0:
            raise invalid("must be < 360 in oscillating mode", key="sector_deg", value=self.sector_deg)
        return self


class SurveyConfig(StrictModel):
    """How much to simulate and how faithfully."""

    seed: Integer(ge=0, le=MAX_SEED) = 0
    fidelity: Choice(*FIDELITY_LEVELS) = "balanced"
    """A fidelity level (scanner_sim.fidelity): sub-rays, shadow rays, record mode."""
    subrays: Choice(*SUBRAY_COUNTS) | None = None
    """Beam sub-rays per pulse, overriding the fidelity level's."""
    beam_profile: Choice(*PROFILES) = "top_hat"
    """Energy across the beam: uniform disc or Gaussian (1/e^2 at the edge)."""
    shadow_rays: bool | None = None
    """Visibility rays from each hit to the receiver, overriding the fidelity level's choice."""
    multiple_scattering: Choice(*MULTIPLE_SCATTERING) | None = None
    """The echo's spread in time and the Monte Carlo's column (``table``) or neither (``none``), overriding the
    fidelity level's choice (muls.water.properties.MULTIPLE_SCATTERING)."""
    start_s: NonNegative = 0.0
    """Start of the pass on the trajectory [s]."""
    duration_s: Positive | None = None
    """Length of the pass [s]; default the whole trajectory."""
    max_pulses: Integer(ge=1) | None = None
    """Stop after this many fired pulses."""
    chunk_pulses: Integer(ge=1) = 10000
    """Pulses per chunk (the slots in which about this many fire): one core simulates a chunk at once (memory
    against overhead)."""

    @property
    def level(self) -> FidelityLevel:
        """The fidelity level with this survey's ``subrays``, ``shadow_rays`` and ``multiple_scattering`` overrides
        applied."""
        level = FIDELITY_LEVELS[self.fidelity]
        return replace(level, subrays=level.subrays if self.subrays is None else self.subrays,
                       shadow_rays=level.shadow_rays if self.shadow_rays is None else self.shadow_rays,
                       multiple_scattering=(level.multiple_scattering if self.multiple_scattering is None
                                            else self.multiple_scattering))


class RosbagConfig(StrictModel):
    """A ROS 2 bag of the pass (``docs/outputs.md``): scan lines as PointCloud2, odometry, tf."""

    frame: Choice("enu", "ned") = "enu"
    """Axes: enu (REP 103: world x east, y north, z up; vehicle x forward, y left, z up) or ned (world x north,
    y east, z down; vehicle x forward, y starboard, z down)."""
    storage: Choice("mcap", "sqlite3") = "mcap"
    """rosbag2 storage: one .mcap file or one SQLite .db3 file."""
    dir: str | None = None
    """The bag's folder; default rosbag/ inside the output folder."""


class OutputConfig(StrictModel):
    """What a pass writes, and where."""

    dir: str | None = None
    """Output folder; default out/<name>."""
    las: bool = True
    """Write the points as points.las."""
    laz: bool = False
    """Write the points as points.laz (compressed by lazrs); with las, both files."""
    copc: bool = False
    """Also write the points as points.copc.laz, a Cloud-Optimised Point Cloud (COPC 1.0) for Potree, QGIS, PDAL."""
    trajectory_csv: bool = True
    """Write the true and estimated poses at 10 Hz as trajectory.csv."""
    waveform_every_n_pulses: Integer(ge=0) = 0
    """Write the full records of every n-th fired pulse to waveforms.npz; 0 = none."""
    split_legs: bool = False
    """One point cloud and one trajectory per survey leg (leg001_points.las, leg001_trajectory.csv...)."""
    rosbag: RosbagConfig | None = None
    """Also write the pass as a ROS 2 bag (``rosbag: {}`` for the defaults); none when absent."""
