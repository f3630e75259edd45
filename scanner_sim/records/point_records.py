"""Point and dropout records: the struct-of-arrays hand-off from ranging to the writers.

One survey pass produces, chunk by chunk, a :class:`PointRecords` (every detected return, with its
ground truth attached) and a :class:`DropoutRecords` (every pulse without a point, with its cause).
Both are frozen dataclasses of equal-length numpy arrays with a back-reference to the pulse
(``pulse_index``), never lists of per-point objects.

Each field is declared once, on its class: name, dtype, shape and where it goes in LAS (a
:class:`LasStandard` dimension with its conversion, a :class:`LasExtra` extra dimension, or nowhere).
:mod:`scanner_sim.io.las` derives the LAS layout from those declarations.

Time is seconds from the start of the pass. How that maps onto the LAS
``gps_time`` field is decided in :mod:`scanner_sim.io.las` and documented in ``docs/outputs.md``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal, get_type_hints

import numpy as np

from muls.ranging.returns import DROPOUT_CAUSES as MULS_DROPOUT_CAUSES

__all__ = [
    "DROPOUT_CAUSES",
    "Column",
    "DropoutRecords",
    "LasExtra",
    "LasStandard",
    "PointRecords",
    "dropout_cause_code",
]

#: Dropout cause names; a cause's index in this tuple is its code in ``DropoutRecords.cause``. The physics
#: decides them (muls.ranging.returns): no_hit, blind_zone, below_threshold, saturated, masked_by_backscatter,
#: outside_gate.
DROPOUT_CAUSES: tuple[str, ...] = MULS_DROPOUT_CAUSES


def dropout_cause_code(name: str) -> int:
    """Code (uint8 value) of the dropout cause called ``name``.

    Raises ValueError naming the valid causes when ``name`` is not one of :data:`DROPOUT_CAUSES`.
    """
    try:
        return DROPOUT_CAUSES.index(name)
    except ValueError:
        raise ValueError(
            f"dropout cause {name!r} is unknown; valid causes: {', '.join(DROPOUT_CAUSES)}"
        ) from None


@dataclass(frozen=True)
class LasStandard:
    """A field stored in standard LAS point format 6 dimensions.

    ``conversion`` names how :mod:`scanner_sim.io.las` turns the field into the dimensions and back:
    ``"copy"`` as is; ``"gps_time"`` plus the writer's GPS time offset [s]; ``"scaled"`` int32 counts
    of the header scale around the header offset (one dimension per column); ``"scan_angle"`` int16 in
    0.006 degree units.
    """

    dimensions: tuple[str, ...]
    conversion: Literal["copy", "gps_time", "scaled", "scan_angle"] = "copy"


@dataclass(frozen=True)
class LasExtra:
    """A field stored as a LAS extra dimension (extra bytes, LAS 1.4 R15 Table 24)."""

    dtype: np.dtype  # type in the file (bool fields are stored as uint8)
    description: str  # at most 32 characters


@dataclass(frozen=True)
class Column:
    """One record field: a (n,) or (n, ``width``) array of ``dtype``, declared on its record class as
    ``name: Annotated[np.ndarray, Column(...)]``.

    ``las`` says where it goes in LAS (None: not stored); ``also`` a standard dimension that carries a copy
    where it fits its range (written only, 0 where it does not fit); ``unknown`` is the value that stands for
    "not known", given to the field when a file does not carry it.
    """

    dtype: np.dtype
    width: int | None = None
    las: LasStandard | LasExtra | None = None
    unknown: float = 0
    also: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "dtype", np.dtype(self.dtype))


def _las(*dimensions: str, conversion: str = "copy") -> LasStandard:
    return LasStandard(dimensions, conversion)


def _extra(dtype, description: str) -> LasExtra:
    return LasExtra(np.dtype(dtype), description)


@functools.cache
def _columns(cls) -> dict[str, Column]:
    hints = get_type_hints(cls, include_extras=True)
    return {f.name: hints[f.name].__metadata__[0] for f in dataclasses.fields(cls)}


def _coerce_field(cls_name: str, name: str, value, dtype: np.dtype, width: int | None) -> np.ndarray:
    """Return ``value`` as a C-contiguous array of ``dtype``; raise ValueError naming the field.

    Integer and boolean fields accept any integer or boolean input whose values fit ``dtype``;
    float fields accept any real numeric input. Strings, objects and lossy casts are refused.
    """
    arr = np.asarray(value)
    kind = arr.dtype.kind
    if arr.size == 0 and kind in "fO":  # np.asarray([]) is float64; allow it for every field
        arr = arr.astype(dtype)
        kind = dtype.kind
    if dtype.kind == "f":
        if kind not in "biuf":
            raise ValueError(
                f"{cls_name}.{name}: dtype {arr.dtype} is not allowed; expected a real numeric "
                f"array convertible to {dtype}"
            )
    elif dtype.kind == "b":
        if kind == "b":
            pass
        elif kind in "iu":
            if arr.size and (arr.min() < 0 or arr.max() > 1):
                raise ValueError(
                    f"{cls_name}.{name}: integer values must be 0 or 1 to convert to bool, "
                    f"got range [{arr.min()}, {arr.max()}]"
                )
        else:
            raise ValueError(f"{cls_name}.{name}: dtype {arr.dtype} is not allowed; expected bool")
    else:  # integer fields
        if kind not in "biu":
            raise ValueError(
                f"{cls_name}.{name}: dtype {arr.dtype} is not allowed; expected an integer array "
                f"convertible to {dtype} (round floats explicitly before building records)"
            )
        if arr.size and kind in "iu" and not np.can_cast(arr.dtype, dtype, casting="safe"):
            info = np.iinfo(dtype)
            lo, hi = arr.min(), arr.max()
            if lo < info.min or hi > info.max:
                raise ValueError(
                    f"{cls_name}.{name}: values span [{lo}, {hi}], outside the {dtype} range "
                    f"[{info.min}, {info.max}]"
                )
    expected = "(n,)" if width is None else f"(n, {width})"
    if width is None and arr.ndim != 1:
        raise ValueError(f"{cls_name}.{name}: shape {arr.shape} is not allowed; expected {expected}")
    if width is not None and (arr.ndim != 2 or arr.shape[1] != width):
        if not (arr.size == 0 and arr.ndim == 1):
            raise ValueError(
                f"{cls_name}.{name}: shape {arr.shape} is not allowed; expected {expected}"
            )
        arr = arr.reshape(0, width)
    return np.ascontiguousarray(arr, dtype=dtype)


class _Records:
    """Shared behaviour of the struct-of-arrays record classes, whose fields are annotated with a :class:`Column`."""

    @classmethod
    def columns(cls) -> dict[str, Column]:
        """Field name -> :class:`Column`, in declaration order."""
        return _columns(cls)

    def __post_init__(self) -> None:
        cls_name = type(self).__name__
        n = None
        first = None
        columns = self.columns()
        given = next((getattr(self, name) for name in columns if getattr(self, name) is not None), ())
        for name, col in columns.items():
            value = getattr(self, name)
            if value is None:  # a field with a default (None): its unknown value on every record
                value = np.full((len(given),) if col.width is None else (len(given), col.width), col.unknown)
            arr = _coerce_field(cls_name, name, value, col.dtype, col.width)
            object.__setattr__(self, name, arr)
            if n is None:
                n, first = arr.shape[0], name
            elif arr.shape[0] != n:
                raise ValueError(
                    f"{cls_name}.{name}: length {arr.shape[0]} differs from {first} "
                    f"(length {n}); every field must hold one entry per record"
                )

    def __len__(self) -> int:
        return int(getattr(self, dataclasses.fields(self)[0].name).shape[0])

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of the record fields, in declaration order."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def empty(cls):
        """Records with zero entries and the right dtypes and shapes."""
        return cls(
            **{
                name: np.zeros((0,) if col.width is None else (0, col.width), dtype=col.dtype)
                for name, col in cls.columns().items()
            }
        )

    @classmethod
    def concatenate(cls, parts: Iterable):
        """Join records end to end (for example the chunks of a pass). An empty list gives ``empty()``."""
        parts = list(parts)
        for i, part in enumerate(parts):
            if not isinstance(part, cls):
                raise ValueError(  # noqa: TRY004 - kept: callers and tests expect ValueError
                    f"{cls.__name__}.concatenate: item {i} is a {type(part).__name__}, "
                    f"expected {cls.__name__}"
                )
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        return cls(
            **{name: np.concatenate([getattr(p, name) for p in parts]) for name in cls.field_names()}
        )

    def select(self, index):
        """Records at ``index`` (a boolean mask of length n, or integer indices)."""
        index = np.asarray(index)
        if index.dtype == bool and index.shape != (len(self),):
            raise ValueError(
                f"{type(self).__name__}.select: mask shape {index.shape} does not match "
                f"the {len(self)} records"
            )
        return type(self)(**{name: getattr(self, name)[index] for name in self.field_names()})

    def as_dict(self) -> dict[str, np.ndarray]:
        """Field name -> array (the arrays themselves, not copies)."""
        return {name: getattr(self, name) for name in self.field_names()}


@dataclass(frozen=True, eq=False)
class PointRecords(_Records):
    """Detected returns of a batch of pulses, one entry per point (n points), with ground truth attached.

    Each field is a (n,) array, ``xyz`` (n, 3); its dtype and LAS placement are declared beside it, the
    LAS columns are tabled in ``docs/outputs.md``.
    """

    #: [s] emission time of the pulse, seconds from the pass start; LAS ``gps_time`` is Adjusted Standard
    #: GPS time, this plus ``LasWriter(gps_time_offset_s=)`` (``docs/outputs.md``).
    gps_time_s: Annotated[np.ndarray, Column(np.float64, las=_las("gps_time", conversion="gps_time"))]
    #: [m] estimated point in the world frame (x east, y north, z up), as the instrument and navigation
    #: would place it: ranging error and navigation noise included.
    xyz: Annotated[np.ndarray, Column(np.float64, 3, las=_las("X", "Y", "Z", conversion="scaled"))]
    #: LAS intensity: peak amplitude of the chosen channel, scaled (``points.intensity_from_power``).
    intensity: Annotated[np.ndarray, Column(np.uint16, las=_las("intensity"))]
    #: 1-based return number within its pulse (1..15), nearest first.
    return_number: Annotated[np.ndarray, Column(np.uint8, las=_las("return_number"))]
    #: Returns detected for that pulse (1..15).
    number_of_returns: Annotated[np.ndarray, Column(np.uint8, las=_las("number_of_returns"))]
    #: Ground-truth class code of the surface hit (the scene label table, ``docs/scene-format.md``).
    classification: Annotated[np.ndarray, Column(np.uint8, las=_las("classification"))]
    #: [deg] mirror angle of the pulse, 0 at nadir.
    scan_angle_deg: Annotated[np.ndarray, Column(np.float32, las=_las("scan_angle", conversion="scan_angle"))]
    #: Detection channel that ranged the point (1..3 for the MUL preset); also LAS ``scanner_channel`` (2 bits).
    channel: Annotated[np.ndarray, Column(np.uint8, las=_extra(np.uint8, "detection channel (1..3)"),
                                          also="scanner_channel")]
    #: [LSB] peak amplitude above the baseline in the chosen channel.
    amplitude_lsb: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "peak amplitude [ADC LSB]"))]
    #: [1] peak amplitude over the channel's noise standard deviation.
    snr: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "peak signal-to-noise ratio"))]
    #: The chosen channel's echo was clipped by the ADC.
    saturated: Annotated[np.ndarray, Column(np.bool_, las=_extra(np.uint8, "1 if the ADC clipped the echo"))]
    #: [m] range from the transmitter to the true hit on the mesh.
    true_range_m: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "range to truth mesh [m]"))]
    #: [m] measured minus true range.
    range_error_m: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "measured - true range [m]"))]
    #: [deg] angle between the beam and the surface normal at the hit.
    incidence_deg: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "incidence angle [deg]"))]
    #: Scene object hit (index in the scene's object list), -1 if none or unknown.
    object_id: Annotated[np.ndarray, Column(np.int32, las=_extra(np.int32, "scene object id (-1 none)"), unknown=-1)]
    #: Survey leg of the pulse, 1-based: the stretch of path from one waypoint to the next (on a lawnmower,
    #: legs 1, 3, 5... are the survey lines and 2, 4... the turns); LAS ``point_source_id``.
    leg: Annotated[np.ndarray, Column(np.uint16, las=_las("point_source_id"))]
    #: Index of the pulse in the pass (back-reference); not stored in LAS, -1 when read back.
    pulse_index: Annotated[np.ndarray, Column(np.int64, unknown=-1)]
    #: [m] total horizontal uncertainty at 95 % (2.45 sigma, bivariate), propagated term by term
    #: (:mod:`scanner_sim.survey.uncertainty`, ``docs/uncertainty.md``); NaN where not known.
    thu_m: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "THU 95% [m]"), unknown=np.nan)] = None
    #: [m] total vertical uncertainty at 95 % (1.96 sigma); NaN where not known.
    tvu_m: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "TVU 95% [m]"), unknown=np.nan)] = None
    #: [m] total vertical uncertainty at 95 % against the surface under the point's own (x, y): the horizontal
    #: errors times the slope of the facet it ranged included; NaN where not known (a near-vertical facet).
    tvu_surface_m: Annotated[np.ndarray, Column(np.float32, las=_extra(np.float32, "TVU vs surface 95% [m]"),
                                                unknown=np.nan)] = None


@dataclass(frozen=True, eq=False)
class DropoutRecords(_Records):
    """Pulses that produced no point, one entry per pulse (n dropped pulses), with the cause."""

    #: Index of the pulse in the pass.
    pulse_index: Annotated[np.ndarray, Column(np.int64)]
    #: [s] emission time, seconds from the pass start.
    time_s: Annotated[np.ndarray, Column(np.float64)]
    #: [m] transmitter position in the world frame, (n, 3).
    origin: Annotated[np.ndarray, Column(np.float64, 3)]
    #: [1] unit beam axis in the world frame, (n, 3).
    direction: Annotated[np.ndarray, Column(np.float32, 3)]
    #: Index into :data:`DROPOUT_CAUSES`.
    cause: Annotated[np.ndarray, Column(np.uint8)]

    CAUSES: ClassVar[tuple[str, ...]] = DROPOUT_CAUSES

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self) and int(self.cause.max()) >= len(DROPOUT_CAUSES):
            bad = int(self.cause[self.cause >= len(DROPOUT_CAUSES)][0])
            raise ValueError(
                f"DropoutRecords.cause: code {bad} is unknown; valid codes are 0..{len(DROPOUT_CAUSES) - 1} "
                f"({', '.join(f'{i}={c}' for i, c in enumerate(DROPOUT_CAUSES))})"
            )

    def counts_by_cause(self) -> dict[str, int]:
        """Number of dropouts per cause name, every cause present (zeros included)."""
        counts = np.bincount(self.cause, minlength=len(DROPOUT_CAUSES))
        return {name: int(counts[i]) for i, name in enumerate(DROPOUT_CAUSES)}
