"""The hit record, declared once: one row per beam sub-ray that hit something, in scan order (pulse-major).

:data:`HIT_FIELDS` names every field with its dtype and width. From it come :class:`HitColumns` (the named tuple
of arrays the compiled kernels fill and read, by field name), :func:`empty_columns` and :class:`Hits` (the frozen
struct-of-arrays the ray stage hands to the survey). A new field is one line here.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np


class HitField(NamedTuple):
    """One field of the hit record: its name, dtype, width (1: shape (n,); 3: shape (n, 3)) and meaning."""

    name: str
    dtype: type
    width: int
    doc: str


HIT_FIELDS: tuple[HitField, ...] = (
    HitField("pulse_index", np.int64, 1, "row of the pulse in the chunk"),
    HitField("subray_index", np.int32, 1, "sub-ray in the beam pattern (0 is the beam axis)"),
    HitField("range_m", np.float64, 1, "[m] distance along the sub-ray from its origin"),
    HitField("point", np.float64, 3, "[m] world position"),
    HitField("normal", np.float32, 3, "unit surface normal facing the incoming ray"),
    HitField("incidence_rad", np.float64, 1, "[rad] angle between the ray and the normal, in [0, pi/2]"),
    HitField("reflectance", np.float64, 1, "Lambertian reflectance at 532 nm"),
    HitField("label", np.int16, 1, "class code (config.materials.LABELS)"),
    HitField("object_id", np.int32, 1, "index into Scene.objects"),
    HitField("surface_id", np.int32, 1, "the smooth surface of the triangle hit (Scene.face_surface): the "
                                        "surface a return's truth is judged on (survey.georeference)"),
    HitField("receiver_weight", np.float64, 1, "the share of the receiver's aperture that sees the hit (its field of "
                                               "view, its lit side, a clear line to it), in [0, 1]"),
    HitField("weight", np.float64, 1, "the sub-ray's share of the pulse energy (a pulse's shares sum to 1)"),
    HitField("echo_range_m", np.float64, 1, "[m] range that times the echo: half the path laser -> hit -> "
                                            "receiver aperture (rays.echoes.echo_range_m)"),
)

#: The hit record's columns by name, in :data:`HIT_FIELDS` order: what the compiled kernels take and fill.
HitColumns = NamedTuple("HitColumns", [(f.name, np.ndarray) for f in HIT_FIELDS])


def _shape(field: HitField, n: int) -> tuple[int, ...]:
    return (n,) if field.width == 1 else (n, field.width)


def empty_columns(n: int, allocate=None) -> HitColumns:
    """Room for n hit rows. ``allocate(name, shape, dtype)`` gives each array (default ``np.empty``), e.g. a
    per-thread workspace that reuses its pages block after block."""
    if allocate is None:
        return HitColumns(*(np.empty(_shape(f, n), f.dtype) for f in HIT_FIELDS))
    return HitColumns(*(allocate(f.name, _shape(f, n), f.dtype) for f in HIT_FIELDS))


def head(columns: HitColumns, k: int) -> HitColumns:
    """The first k rows of ``columns`` (views)."""
    return HitColumns(*(a[:k] for a in columns))


class _HitsMethods:
    def __len__(self) -> int:
        return int(self.range_m.shape[0])

    def columns(self) -> HitColumns:
        """The fields as :class:`HitColumns` (the arrays themselves)."""
        return HitColumns(*(getattr(self, f.name) for f in HIT_FIELDS))

    @classmethod
    def from_columns(cls, columns: HitColumns, n_pulses: int, n_subrays: int, copy: bool = False) -> Hits:
        """Hits of ``columns``, copied when ``copy`` (scratch arrays that will be reused)."""
        return cls(*((a.copy() for a in columns) if copy else columns), n_pulses=n_pulses, n_subrays=n_subrays)

    @classmethod
    def concatenate(cls, parts: list[Hits], n_pulses: int) -> Hits:
        """The rows of ``parts`` one after the other (their pulse indices already chunk-wide)."""
        if len(parts) == 1:
            return dataclasses.replace(parts[0], n_pulses=n_pulses)
        return cls(*(np.concatenate([getattr(h, f.name) for h in parts]) for f in HIT_FIELDS), n_pulses=n_pulses,
                   n_subrays=parts[0].n_subrays)

    def seen_fraction(self) -> np.ndarray:
        """(n_pulses,) share of each pulse's energy that hit something the receiver sees (ray-cast overlap)."""
        return np.bincount(self.pulse_index, weights=self.weight * self.receiver_weight, minlength=self.n_pulses)

    def hit_fraction(self) -> np.ndarray:
        """(n_pulses,) share of each pulse's energy that hit anything."""
        return np.bincount(self.pulse_index, weights=self.weight, minlength=self.n_pulses)


Hits = dataclasses.make_dataclass(
    "Hits", [(f.name, np.ndarray) for f in HIT_FIELDS] + [("n_pulses", int), ("n_subrays", int)],
    bases=(_HitsMethods,), frozen=True)
Hits.__module__ = __name__
Hits.__doc__ = ("First hits of beam sub-rays, one row per sub-ray that hit, in scan order (pulse-major); a pulse "
                "with no row is a ``no_hit``. n_pulses: pulses of the chunk; n_subrays: sub-rays per pulse. Fields "
                "(n,) or (n, 3):\n\n" + "\n".join(f"- {f.name} ({np.dtype(f.dtype).name}): {f.doc}" for f in HIT_FIELDS))
