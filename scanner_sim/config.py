"""Scene files: YAML -> validated, frozen dataclasses, converted once (DESIGN.md section 3).

The format is versioned (``format_version: 1``) and strict: every key carries its unit, an unknown key is
rejected with the nearest valid key suggested, and every bad value raises :class:`ConfigError` (a
``ValueError``) with one line naming the dotted key, the value and what is allowed. The full format, with a
commented example, is in ``docs/scene-format.md``.

Entry points: :func:`load_scene` (a shipped scene's name or a path) and :func:`parse_scene` (a mapping).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import yaml

from muls.errors import ParameterError

from .fidelity import FIDELITY_LEVELS, FidelityLevel

FORMAT_VERSION = 1
SCENES_DIR = Path(__file__).resolve().parent.parent / "scenes"


class ConfigError(ParameterError):
    """A scene file is wrong; the one-line message names the key, the value and what is allowed."""


# --------------------------------------------------------------------------------------------------------
# Value checkers: f(value, path) -> converted value. Each raises ConfigError naming the path.
# --------------------------------------------------------------------------------------------------------

def _fail(path: str, value: Any, allowed: str):
    raise ConfigError(f"{path} = {value!r}: {allowed}")


def _to_float(value, path, allowed):
    if isinstance(value, bool):
        _fail(path, value, allowed)
    if isinstance(value, str):  # PyYAML reads 1e-3 (no dot) as a string
        try:
            value = float(value)
        except ValueError:
            _fail(path, value, allowed)
    if not isinstance(value, (int, float)):
        _fail(path, value, allowed)
    value = float(value)
    if not math.isfinite(value):
        _fail(path, value, f"must be a finite number ({allowed.removeprefix('must be ')})")
    return value


def number(lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
           optional: bool = False):
    """A finite float in [lo, hi] (open ends as asked); None allowed when ``optional``."""
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi:g}")
    allowed = "must be a number" + (" " + " and ".join(parts) if parts else "")

    def check(value, path):
        if value is None and optional:
            return None
        v = _to_float(value, path, allowed)
        if lo is not None and (v < lo or (lo_open and v == lo)):
            _fail(path, v, allowed)
        if hi is not None and (v > hi or (hi_open and v == hi)):
            _fail(path, v, allowed)
        return v

    return check


POSITIVE = number(0.0, lo_open=True)
NON_NEGATIVE = number(0.0)
FRACTION = number(0.0, 1.0)
ANY_NUMBER = number()


def integer(lo: int | None = None, hi: int | None = None, optional: bool = False, choices=None):
    if choices is not None:
        allowed = f"must be one of {', '.join(map(str, choices))}"
    else:
        allowed = "must be an integer" + (f" >= {lo}" if lo is not None else "") + (f" <= {hi}" if hi is not None else "")

    def check(value, path):
        if value is None and optional:
            return None
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            _fail(path, value, allowed)
        if (lo is not None and value < lo) or (hi is not None and value > hi) or (choices and value not in choices):
            _fail(path, value, allowed)
        return value

    return check


def choice(options, optional: bool = False):
    allowed = f"must be one of {', '.join(map(repr, options))}"

    def check(value, path):
        if value is None and optional:
            return None
        if value not in options:
            hint = difflib.get_close_matches(str(value), list(options), n=1)
            _fail(path, value, allowed + (f" (did you mean {hint[0]!r}?)" if hint else ""))
        return value

    return check


def text(optional: bool = False):
    def check(value, path):
        if value is None and optional:
            return None
        if not isinstance(value, str):
            _fail(path, value, "must be a text string")
        return value

    return check


def boolean(optional: bool = False):
    def check(value, path):
        if value is None and optional:
            return None
        if not isinstance(value, bool):
            _fail(path, value, "must be true or false")
        return value

    return check


def vector(sizes=(3,), element=ANY_NUMBER, optional: bool = False):
    """A list of numbers whose length is one of ``sizes``; returned as a tuple of floats."""
    allowed = f"must be a list of {' or '.join(map(str, sizes))} numbers"

    def check(value, path):
        if value is None and optional:
            return None
        if not isinstance(value, (list, tuple)) or len(value) not in sizes:
            _fail(path, value, allowed)
        return tuple(element(v, f"{path}[{i}]") for i, v in enumerate(value))

    return check


def point_list(sizes=(2, 3), min_count: int = 2, optional: bool = False):
    """A list of at least ``min_count`` points, each of a length in ``sizes`` (all the same length)."""
    one = vector(sizes)
    allowed = f"must be a list of at least {min_count} points, each a list of {' or '.join(map(str, sizes))} numbers"

    def check(value, path):
        if value is None and optional:
            return None
        if not isinstance(value, (list, tuple)) or len(value) < min_count:
            _fail(path, value, allowed)
        points = tuple(one(v, f"{path}[{i}]") for i, v in enumerate(value))
        if len({len(p) for p in points}) != 1:
            _fail(path, value, "points must all have the same number of coordinates")
        return points

    return check


def fraction_or_list(value, path):
    """A fraction in [0, 1], or a list of them (one per cable point)."""
    if isinstance(value, (list, tuple)):
        if not value:
            _fail(path, value, "must be a number in [0, 1] or a non-empty list of them")
        return tuple(FRACTION(v, f"{path}[{i}]") for i, v in enumerate(value))
    return FRACTION(value, path)


def section(cls, optional: bool = False):
    def check(value, path):
        if value is None and optional:
            return None
        return build(cls, value, path)

    return check


def _spec(check, default=MISSING, doc: str = ""):
    """A dataclass field whose YAML value is converted by ``check``."""
    if default is MISSING:
        return field(metadata={"check": check, "doc": doc})
    if isinstance(default, (list, dict)):
        raise TypeError("use tuples for defaults")
    return field(default=default, metadata={"check": check, "doc": doc})


def _section_field(cls, optional: bool = False):
    if optional:
        return field(default=None, metadata={"check": section(cls, optional=True)})
    return field(default_factory=lambda: build(cls, {}, cls.__name__), metadata={"check": section(cls)})


def keys_of(cls) -> list[str]:
    return [f.name for f in fields(cls) if "check" in f.metadata]


def build(cls, data, path: str):
    """Convert mapping ``data`` into dataclass ``cls``; unknown keys are rejected with a suggestion."""
    if data is None:
        data = {}
    valid = keys_of(cls)
    if not isinstance(data, dict):
        _fail(path, data, f"must be a mapping with keys {', '.join(valid)}")
    values = {}
    for key in data:
        if key not in valid:
            hint = difflib.get_close_matches(str(key), valid, n=1, cutoff=0.5)
            where = f"{path}.{key}" if path else str(key)
            suggestion = f"did you mean {hint[0]!r}? " if hint else ""
            raise ConfigError(f"{where}: unknown key; {suggestion}(allowed: {', '.join(valid)})")
    for f in fields(cls):
        if "check" not in f.metadata:
            continue
        key_path = f"{path}.{f.name}" if path else f.name
        if f.name in data:
            values[f.name] = f.metadata["check"](data[f.name], key_path)
        elif f.default is MISSING and f.default_factory is MISSING:
            raise ConfigError(f"{key_path}: missing required key")
    obj = cls(**values)
    validate = getattr(obj, "_validate", None)
    if validate is not None:
        validate(path)
    return obj


# --------------------------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class WaterConfig:
    """The water: a preset name, or its optical properties at 532 nm."""

    preset: str | None = _spec(text(optional=True), None)
    absorption_per_m: float | None = _spec(number(0.0, optional=True), None)
    scattering_per_m: float | None = _spec(number(0.0, optional=True), None)
    attenuation_per_m: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    group_index: float | None = _spec(number(1.0, 2.0, optional=True), None)
    beta_pi_per_m_sr: float | None = _spec(number(0.0, optional=True), None)
    attenuation_model: str | None = _spec(choice(("k_lidar", "c", "kd"), optional=True), None)
    backscatter_model: str | None = _spec(choice(("measured", "hg", "eq5"), optional=True), None)

    def _validate(self, path):
        from muls.water import WATER_PRESETS

        if self.preset is not None:
            choice(tuple(sorted(WATER_PRESETS)))(self.preset, f"{path}.preset")
            if any(v is not None for v in (self.absorption_per_m, self.scattering_per_m, self.attenuation_per_m,
                                          self.group_index, self.beta_pi_per_m_sr)):
                raise ConfigError(f"{path}: give a preset or optical properties, not both "
                                  "(a preset takes only attenuation_model and backscatter_model)")
            return
        a, b, c = self.absorption_per_m, self.scattering_per_m, self.attenuation_per_m
        if a is None or (b is None) == (c is None):
            raise ConfigError(f"{path} = {{absorption_per_m: {a}, scattering_per_m: {b}, attenuation_per_m: {c}}}: "
                              "give a preset name, or absorption_per_m with exactly one of scattering_per_m and "
                              "attenuation_per_m")
        if c is not None and a > c:
            raise ConfigError(f"{path}.absorption_per_m = {a!r}: must be <= attenuation_per_m ({c!r})")
        if b is not None and a + b <= 0.0:
            raise ConfigError(f"{path}: absorption_per_m + scattering_per_m = 0: attenuation must be > 0")

    def to_water(self, name: str = "custom"):
        """The :class:`muls.water.Water` this section describes."""
        from dataclasses import replace

        from muls.water import GROUP_INDEX_SEAWATER, Water, water_preset

        if self.preset is not None:
            water = water_preset(self.preset)
        else:
            kw = dict(group_index=self.group_index or GROUP_INDEX_SEAWATER,
                      beta_pi_measured_per_m_sr=self.beta_pi_per_m_sr, source="scene file")
            if self.attenuation_per_m is not None:
                water = Water.from_attenuation(name, self.attenuation_per_m, self.absorption_per_m, **kw)
            else:
                water = Water(name, self.absorption_per_m, self.scattering_per_m, **kw)
        if self.attenuation_model or self.backscatter_model:
            water = replace(water, attenuation_model=self.attenuation_model or water.attenuation_model,
                            backscatter_model=self.backscatter_model or water.backscatter_model)
        return water


def _water(value, path):
    if isinstance(value, str):
        return build(WaterConfig, {"preset": value}, path)
    return build(WaterConfig, value, path)


@dataclass(frozen=True, kw_only=True)
class InstrumentConfig:
    """A muls instrument preset plus overrides (units in the keys)."""

    preset: str = _spec(choice(("mul2023", "single_channel", "coaxial")), "mul2023")
    gate_delay_ns: float | None = _spec(number(0.0, optional=True), None)
    gate_width_ns: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    pulse_energy_j: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    pulse_width_ns: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    beam_diameter_m: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    beam_divergence_full_rad: float | None = _spec(number(0.0, math.pi, hi_open=True, optional=True), None)
    fov_full_rad: float | None = _spec(number(0.0, math.pi, lo_open=True, hi_open=True, optional=True), None)
    receiver_offset_m: float | None = _spec(number(0.0, optional=True), None)
    receiver_area_m2: float | None = _spec(number(0.0, lo_open=True, optional=True), None)

    def _validate(self, path):
        if (self.gate_delay_ns is None) != (self.gate_width_ns is None):
            raise ConfigError(f"{path}: give both gate_delay_ns and gate_width_ns, or neither")

    def to_instrument(self, water=None):
        """The :class:`muls.instrument.Instrument` with the overrides applied (muls imported lazily)."""
        from dataclasses import replace

        from muls.instrument import instrument_preset

        inst = instrument_preset(self.preset, water)
        tx, rx = {}, {}
        if self.pulse_energy_j is not None:
            tx["pulse_energy_j"] = self.pulse_energy_j
        if self.pulse_width_ns is not None:
            tx["pulse_width_s"] = self.pulse_width_ns * 1e-9
        if self.beam_diameter_m is not None:
            tx["beam_diameter_m"] = self.beam_diameter_m
        if self.beam_divergence_full_rad is not None:
            tx["beam_divergence_full_rad"] = self.beam_divergence_full_rad
        if self.fov_full_rad is not None:
            rx["fov_full_rad"] = self.fov_full_rad
        if self.receiver_offset_m is not None:
            rx["offset_m"] = self.receiver_offset_m
        if self.receiver_area_m2 is not None:
            rx["area_m2"] = self.receiver_area_m2
        inst = replace(inst, transmitter=replace(inst.transmitter, **tx), receiver=replace(inst.receiver, **rx))
        if self.gate_delay_ns is not None:
            for ch in inst.channels:
                if ch.gated:
                    inst = inst.with_channel(ch.name, gate_delay_s=self.gate_delay_ns * 1e-9,
                                             gate_width_s=self.gate_width_ns * 1e-9)
        return inst


def _material_fields_validate(obj, path):
    from .materials import LABELS, MATERIALS

    if obj.material is not None:
        choice(tuple(MATERIALS))(obj.material, f"{path}.material")
    if obj.material is None and obj.reflectance is None:
        raise ConfigError(f"{path}: give a material ({', '.join(MATERIALS)}) or a reflectance in [0, 1]")
    choice(tuple(LABELS))(obj.label, f"{path}.label")


def _reflectance_of(obj) -> float:
    from .materials import MATERIALS

    return obj.reflectance if obj.reflectance is not None else MATERIALS[obj.material].reflectance


@dataclass(frozen=True, kw_only=True)
class ReliefConfig:
    """Fractal relief: rms height [m], largest feature wavelength [m], Hurst exponent."""

    rms_m: float = _spec(NON_NEGATIVE, 0.2)
    wavelength_m: float = _spec(POSITIVE, 10.0)
    hurst: float = _spec(number(0.0, 1.0, lo_open=True), 0.7)


@dataclass(frozen=True, kw_only=True)
class RipplesConfig:
    """Sand ripples: amplitude [m] (half the trough-to-crest height), wavelength [m], crest direction [deg
    from +x, counter-clockwise], crest meander [wavelengths]."""

    amplitude_m: float = _spec(NON_NEGATIVE, 0.0)
    wavelength_m: float = _spec(POSITIVE, 0.6)
    crest_deg: float = _spec(ANY_NUMBER, 0.0)
    sinuosity: float = _spec(NON_NEGATIVE, 0.15)


@dataclass(frozen=True, kw_only=True)
class RocksConfig:
    count: int = _spec(integer(0, 10000), 0)
    radius_min_m: float = _spec(POSITIVE, 0.1)
    radius_max_m: float = _spec(POSITIVE, 0.4)
    material: str | None = _spec(text(optional=True), "rock")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "rock")

    def _validate(self, path):
        if self.radius_max_m < self.radius_min_m:
            raise ConfigError(f"{path}.radius_max_m = {self.radius_max_m!r}: must be >= radius_min_m "
                              f"({self.radius_min_m!r})")
        _material_fields_validate(self, path)


MAX_SEABED_TRIANGLES = 2_000_000


@dataclass(frozen=True, kw_only=True)
class SeabedConfig:
    """Procedural seabed over a rectangle: mean depth, relief, ripples, rocks, material."""

    size_m: tuple = _spec(vector((2,), POSITIVE))
    center_m: tuple = _spec(vector((2,)), (0.0, 0.0))
    resolution_m: float = _spec(POSITIVE, 0.1)
    depth_m: float = _spec(NON_NEGATIVE, 20.0)
    seed: int = _spec(integer(0), 0)
    material: str | None = _spec(text(optional=True), "terrigenous_sand")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "seabed")
    relief: ReliefConfig = _section_field(ReliefConfig)
    ripples: RipplesConfig = _section_field(RipplesConfig)
    rocks: RocksConfig = _section_field(RocksConfig)

    def _validate(self, path):
        _material_fields_validate(self, path)
        nx = self.size_m[0] / self.resolution_m + 1
        ny = self.size_m[1] / self.resolution_m + 1
        if nx < 2 or ny < 2:
            raise ConfigError(f"{path}.resolution_m = {self.resolution_m!r}: must be at most the seabed size "
                              f"{list(self.size_m)}")
        tris = 2 * (nx - 1) * (ny - 1)
        if tris > MAX_SEABED_TRIANGLES:
            raise ConfigError(f"{path}.resolution_m = {self.resolution_m!r}: gives {tris:,.0f} triangles over "
                              f"{list(self.size_m)} m, more than the {MAX_SEABED_TRIANGLES:,} allowed; use a "
                              "coarser resolution or a smaller seabed")


@dataclass(frozen=True, kw_only=True)
class CableObject:
    """A tube swept along a smooth curve through ``points_m``, lying on the seabed, partly buried."""

    type: str = _spec(choice(("cable",)), "cable")
    name: str = _spec(text(), "cable")
    points_m: tuple = _spec(point_list((2, 3), 2))
    diameter_m: float = _spec(POSITIVE, 0.05)
    burial_fraction: Any = _spec(fraction_or_list, 0.3)
    sides: int = _spec(integer(3, 64), 12)
    step_m: float = _spec(POSITIVE, 0.05)
    stiffness_length_m: float = _spec(NON_NEGATIVE, 0.5)
    material: str | None = _spec(text(optional=True), "polyethylene")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "cable")

    def _validate(self, path):
        _material_fields_validate(self, path)
        if isinstance(self.burial_fraction, tuple) and len(self.burial_fraction) != len(self.points_m):
            raise ConfigError(f"{path}.burial_fraction = {list(self.burial_fraction)!r}: must be one number or "
                              f"one per point ({len(self.points_m)})")


@dataclass(frozen=True, kw_only=True)
class MooredMineObject:
    """A sphere moored on a tether: its centre ``height_m`` above the seabed at ``position_m``."""

    type: str = _spec(choice(("moored_mine",)), "moored_mine")
    name: str = _spec(text(), "moored_mine")
    position_m: tuple = _spec(vector((2, 3)))
    radius_m: float = _spec(POSITIVE, 0.5)
    height_m: float = _spec(POSITIVE, 2.0)
    tether_diameter_m: float = _spec(POSITIVE, 0.02)
    material: str | None = _spec(text(optional=True), "painted_steel")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "mine")

    def _validate(self, path):
        _material_fields_validate(self, path)
        if self.height_m <= self.radius_m:
            raise ConfigError(f"{path}.height_m = {self.height_m!r}: must be > radius_m ({self.radius_m!r})")


@dataclass(frozen=True, kw_only=True)
class CylinderMineObject:
    """A cylinder lying on the seabed, axis horizontal along compass ``heading_deg``."""

    type: str = _spec(choice(("cylinder_mine",)), "cylinder_mine")
    name: str = _spec(text(), "cylinder_mine")
    position_m: tuple = _spec(vector((2, 3)))
    radius_m: float = _spec(POSITIVE, 0.27)
    length_m: float = _spec(POSITIVE, 1.8)
    heading_deg: float = _spec(ANY_NUMBER, 0.0)
    burial_fraction: float = _spec(FRACTION, 0.0)
    material: str | None = _spec(text(optional=True), "painted_steel")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "mine")

    def _validate(self, path):
        _material_fields_validate(self, path)


@dataclass(frozen=True, kw_only=True)
class ConeMineObject:
    """A truncated cone standing on the seabed (bottom mine)."""

    type: str = _spec(choice(("cone_mine",)), "cone_mine")
    name: str = _spec(text(), "cone_mine")
    position_m: tuple = _spec(vector((2, 3)))
    bottom_radius_m: float = _spec(POSITIVE, 0.5)
    top_radius_m: float = _spec(NON_NEGATIVE, 0.2)
    height_m: float = _spec(POSITIVE, 0.4)
    burial_fraction: float = _spec(FRACTION, 0.0)
    material: str | None = _spec(text(optional=True), "painted_steel")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "mine")

    def _validate(self, path):
        _material_fields_validate(self, path)


@dataclass(frozen=True, kw_only=True)
class PanelObject:
    """A flat rectangle: centre [m], size (width, height) [m], unit-free normal, and an 'up' hint for its
    height direction."""

    type: str = _spec(choice(("panel",)), "panel")
    name: str = _spec(text(), "panel")
    center_m: tuple = _spec(vector((3,)))
    size_m: tuple = _spec(vector((2,), POSITIVE), (1.0, 1.0))
    normal: tuple = _spec(vector((3,)), (0.0, 0.0, 1.0))
    up: tuple = _spec(vector((3,)), (0.0, 1.0, 0.0))
    material: str | None = _spec(text(optional=True), "black_painted_aluminium")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "panel")

    def _validate(self, path):
        _material_fields_validate(self, path)
        if math.hypot(*self.normal) == 0.0:
            raise ConfigError(f"{path}.normal = {list(self.normal)!r}: must be a non-zero vector")


@dataclass(frozen=True, kw_only=True)
class MeshObject:
    """Any mesh file trimesh reads, scaled, rotated (roll, pitch, yaw about x, y, z [deg]) then translated.

    ``translate_m`` with two numbers puts the mesh's lowest point on the seabed at that (x, y).
    ``file`` is relative to the scene file's folder.
    """

    type: str = _spec(choice(("mesh",)), "mesh")
    name: str = _spec(text(), "mesh")
    file: str = _spec(text())
    translate_m: tuple = _spec(vector((2, 3)), (0.0, 0.0, 0.0))
    rotate_deg: tuple = _spec(vector((3,)), (0.0, 0.0, 0.0))
    scale: float = _spec(POSITIVE, 1.0)
    material: str | None = _spec(text(optional=True), "painted_steel")
    reflectance: float | None = _spec(number(0.0, 1.0, optional=True), None)
    label: str = _spec(text(), "wreck")
    resolved_path: Path | None = field(default=None, compare=False)

    def _validate(self, path):
        _material_fields_validate(self, path)


OBJECT_TYPES = {
    "cable": CableObject,
    "moored_mine": MooredMineObject,
    "cylinder_mine": CylinderMineObject,
    "cone_mine": ConeMineObject,
    "panel": PanelObject,
    "mesh": MeshObject,
}


def _objects(value, path):
    if value is None:
        return ()
    if not isinstance(value, list):
        _fail(path, value, "must be a list of objects, each with a 'type'")
    out = []
    for i, item in enumerate(value):
        p = f"{path}[{i}]"
        if not isinstance(item, dict) or "type" not in item:
            _fail(p, item, f"must be a mapping with a 'type' among {', '.join(OBJECT_TYPES)}")
        kind = choice(tuple(OBJECT_TYPES))(item["type"], f"{p}.type")
        out.append(build(OBJECT_TYPES[kind], item, p))
    return tuple(out)


@dataclass(frozen=True, kw_only=True)
class LawnmowerConfig:
    """Survey lines over a rectangle: centre [m], size (along the lines, across) [m], line direction as a
    compass heading [deg], line spacing [m]."""

    center_m: tuple = _spec(vector((2,)), (0.0, 0.0))
    size_m: tuple = _spec(vector((2,), POSITIVE))
    heading_deg: float = _spec(ANY_NUMBER, 0.0)
    line_spacing_m: float = _spec(POSITIVE, 4.0)


@dataclass(frozen=True, kw_only=True)
class AttitudeConfig:
    """Attitude on top of the track: constant offsets and sinusoidal motion [deg, s]. Pitch nose-up and roll
    starboard-down are positive."""

    pitch_deg: float = _spec(number(-90.0, 90.0), 0.0)
    roll_deg: float = _spec(number(-90.0, 90.0), 0.0)
    pitch_amplitude_deg: float = _spec(number(0.0, 45.0), 0.0)
    pitch_period_s: float = _spec(POSITIVE, 8.0)
    roll_amplitude_deg: float = _spec(number(0.0, 45.0), 0.0)
    roll_period_s: float = _spec(POSITIVE, 6.0)
    follow_terrain_pitch: bool = _spec(boolean(), True)


@dataclass(frozen=True, kw_only=True)
class NavigationNoiseConfig:
    """Navigation errors: first-order Gauss-Markov processes with these standard deviations and correlation
    time, sampled at ``rate_hz`` and interpolated; seeded."""

    position_sigma_m: float = _spec(NON_NEGATIVE, 0.0)
    depth_sigma_m: float = _spec(NON_NEGATIVE, 0.0)
    attitude_sigma_deg: float = _spec(NON_NEGATIVE, 0.0)
    heading_sigma_deg: float = _spec(NON_NEGATIVE, 0.0)
    correlation_time_s: float = _spec(POSITIVE, 10.0)
    rate_hz: float = _spec(POSITIVE, 100.0)
    seed: int = _spec(integer(0), 0)


PLATFORM_MODES = ("waypoints", "lawnmower", "static")


@dataclass(frozen=True, kw_only=True)
class PlatformConfig:
    """The vehicle: a trajectory mode, speed, vertical reference, attitude and navigation noise."""

    mode: str = _spec(choice(PLATFORM_MODES), "waypoints")
    speed_m_s: float = _spec(POSITIVE, 1.0)
    waypoints_m: tuple | None = _spec(point_list((2,), 2, optional=True), None)
    lawnmower: LawnmowerConfig | None = _section_field(LawnmowerConfig, optional=True)
    position_m: tuple | None = _spec(vector((2, 3), optional=True), None)
    heading_deg: float = _spec(ANY_NUMBER, 0.0)
    altitude_m: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    depth_m: float | None = _spec(number(0.0, optional=True), None)
    follow_length_m: float = _spec(POSITIVE, 1.5)
    turn_length_m: float = _spec(NON_NEGATIVE, 1.0)
    attitude: AttitudeConfig = _section_field(AttitudeConfig)
    navigation_noise: NavigationNoiseConfig = _section_field(NavigationNoiseConfig)

    def _validate(self, path):
        if self.mode == "waypoints" and self.waypoints_m is None:
            raise ConfigError(f"{path}.waypoints_m: missing; mode 'waypoints' needs a list of at least 2 [x, y] points")
        if self.mode == "lawnmower" and self.lawnmower is None:
            raise ConfigError(f"{path}.lawnmower: missing; mode 'lawnmower' needs center_m, size_m, heading_deg, "
                              "line_spacing_m")
        if self.mode == "static" and self.position_m is None:
            raise ConfigError(f"{path}.position_m: missing; mode 'static' needs [x, y, z] or [x, y] with altitude_m "
                              "or depth_m")
        needs_vertical = not (self.mode == "static" and self.position_m is not None and len(self.position_m) == 3)
        given = [k for k in ("altitude_m", "depth_m") if getattr(self, k) is not None]
        if needs_vertical and len(given) != 1:
            raise ConfigError(f"{path}: give exactly one of altitude_m (follow the seabed) and depth_m (constant "
                              f"depth), got {given or 'neither'}")
        if not needs_vertical and given:
            raise ConfigError(f"{path}.{given[0]}: not allowed with a 3-D static position_m")


SCAN_MODES = ("continuous", "oscillating", "static")


@dataclass(frozen=True, kw_only=True)
class ScannerConfig:
    """The RM3/RM4 shaft: mode, rates, sector [deg of scan angle from nadir], mounting on the vehicle."""

    mode: str = _spec(choice(SCAN_MODES), "continuous")
    scan_rate_hz: float = _spec(POSITIVE, 10.0)
    sector_deg: float = _spec(number(0.0, 360.0, lo_open=True), 90.0)
    center_deg: float = _spec(number(-180.0, 180.0), 0.0)
    aim_deg: float = _spec(number(-180.0, 180.0), 0.0)
    oscillation: str = _spec(choice(("triangle", "sine")), "triangle")
    pulse_rate_hz: float | None = _spec(number(0.0, 1e7, lo_open=True, optional=True), None)
    mounting: str = _spec(choice(("along_track", "across_track")), "along_track")
    mount_position_m: tuple = _spec(vector((3,)), (0.0, 0.0, 0.0))

    def _validate(self, path):
        if self.mode == "oscillating" and self.sector_deg >= 360.0:
            raise ConfigError(f"{path}.sector_deg = {self.sector_deg!r}: must be < 360 in oscillating mode")


@dataclass(frozen=True, kw_only=True)
class SurveyConfig:
    """How much to simulate and how faithfully."""

    seed: int = _spec(integer(0), 0)
    fidelity: str = _spec(choice(tuple(FIDELITY_LEVELS)), "balanced")
    subrays: int | None = _spec(integer(optional=True, choices=(1, 7, 19, 37, 61, 91, 127, 169, 217)), None)
    beam_profile: str = _spec(choice(("top_hat", "gaussian")), "top_hat")
    shadow_rays: bool | None = _spec(boolean(optional=True), None)
    start_s: float = _spec(NON_NEGATIVE, 0.0)
    duration_s: float | None = _spec(number(0.0, lo_open=True, optional=True), None)
    max_pulses: int | None = _spec(integer(1, optional=True), None)
    chunk_pulses: int = _spec(integer(1), 20000)

    @property
    def level(self) -> FidelityLevel:
        """The fidelity level with this survey's ``subrays`` and ``shadow_rays`` overrides applied."""
        level = FIDELITY_LEVELS[self.fidelity]
        return replace(level, subrays=level.subrays if self.subrays is None else self.subrays,
                       shadow_rays=level.shadow_rays if self.shadow_rays is None else self.shadow_rays)


@dataclass(frozen=True, kw_only=True)
class OutputConfig:
    dir: str | None = _spec(text(optional=True), None)
    las: bool = _spec(boolean(), True)
    laz: bool = _spec(boolean(), False)
    trajectory_csv: bool = _spec(boolean(), True)
    waveform_every_n_pulses: int = _spec(integer(0), 0)
    waveform_sample_rate_hz: float | None = _spec(number(0.0, lo_open=True, optional=True), None)


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """A whole scene file, validated. ``source_path`` is the file it came from (None for a mapping)."""

    format_version: int = _spec(integer(choices=(FORMAT_VERSION,)))
    name: str = _spec(text())
    platform: PlatformConfig = _spec(section(PlatformConfig))
    description: str = _spec(text(), "")
    water: WaterConfig = field(default_factory=lambda: build(WaterConfig, {"preset": "coastal_ocean"}, "water"),
                               metadata={"check": _water})
    instrument: InstrumentConfig = _section_field(InstrumentConfig)
    seabed: SeabedConfig | None = _section_field(SeabedConfig, optional=True)
    objects: tuple = _spec(_objects, ())
    scanner: ScannerConfig = _section_field(ScannerConfig)
    survey: SurveyConfig = _section_field(SurveyConfig)
    output: OutputConfig = _section_field(OutputConfig)
    source_path: Path | None = field(default=None, compare=False)

    def _validate(self, path):
        if self.survey.duration_s is None and self.survey.max_pulses is None and self.platform.mode == "static":
            raise ConfigError("survey: a static platform needs survey.duration_s or survey.max_pulses")
        needs_seabed = self.platform.altitude_m is not None or any(
            isinstance(o, (CableObject, MooredMineObject, CylinderMineObject, ConeMineObject)) and
            (len(getattr(o, "position_m", (0, 0, 0))) == 2 or isinstance(o, CableObject))
            for o in self.objects)
        if needs_seabed and self.seabed is None:
            raise ConfigError("seabed: missing; altitude_m and objects placed on the bottom need a seabed section")

    def water_model(self):
        """The :class:`muls.water.Water` of this scene."""
        return self.water.to_water(f"{self.name}_water")

    def instrument_model(self):
        """The :class:`muls.instrument.Instrument` of this scene (gate and other overrides applied)."""
        return self.instrument.to_instrument(self.water_model())

    @property
    def output_dir(self) -> str:
        return self.output.dir or f"out/{self.name}"


# --------------------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------------------

class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate keys (PyYAML silently keeps the last one)."""


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise ConfigError(f"{key}: duplicate key at line {key_node.start_mark.line + 1}")
        seen.add(key)
    return loader.construct_mapping(node, deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def shipped_scenes() -> dict[str, Path]:
    """Shipped scene names -> their files, from the top-level ``scenes/`` folder."""
    return {p.stem: p for p in sorted(SCENES_DIR.glob("*.yaml"))}


def resolve_scene_path(name_or_path: str | Path) -> Path:
    """A shipped scene's name, or a path to a YAML file."""
    text_ = str(name_or_path)
    path = Path(text_)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError(f"scene = {text_!r}: file not found")
        return path
    scenes = shipped_scenes()
    if text_ in scenes:
        return scenes[text_]
    hint = difflib.get_close_matches(text_, list(scenes), n=1)
    raise ConfigError(f"scene = {text_!r}: not a file nor a shipped scene; "
                      + (f"did you mean {hint[0]!r}? " if hint else "") + f"(shipped: {', '.join(scenes)})")


def load_scene(name_or_path: str | Path) -> SceneConfig:
    """Read and validate a scene file (by shipped name or path). Raises :class:`ConfigError` (one line)."""
    path = resolve_scene_path(name_or_path)
    try:
        data = yaml.load(path.read_text(), Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{path.name}: YAML syntax error{where}: {problem}") from None
    return parse_scene(data, base_dir=path.parent, source_path=path)


def parse_scene(data: dict, base_dir: Path | None = None, source_path: Path | None = None) -> SceneConfig:
    """Validate a scene mapping. Mesh files are resolved against ``base_dir`` and must exist."""
    from dataclasses import replace

    if not isinstance(data, dict):
        raise ConfigError(f"scene = {type(data).__name__}: must be a mapping with format_version, name, platform, ...")
    if "format_version" in data:
        integer(choices=(FORMAT_VERSION,))(data["format_version"], "format_version")
    cfg = build(SceneConfig, data, "")
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    objects = []
    for i, obj in enumerate(cfg.objects):
        if isinstance(obj, MeshObject):
            p = Path(obj.file)
            p = p if p.is_absolute() else base / p
            if not p.is_file():
                raise ConfigError(f"objects[{i}].file = {obj.file!r}: file not found (looked for {p}); "
                                  "give a path relative to the scene file")
            obj = replace(obj, resolved_path=p)
        objects.append(obj)
    return replace(cfg, objects=tuple(objects), source_path=source_path)


def reflectance_of(obj) -> float:
    """Reflectance at 532 nm of a seabed, rocks or object section: ``reflectance`` if given, else the
    material's."""
    return _reflectance_of(obj)
