"""Point and dropout records: the struct-of-arrays hand-off from ranging to the writers.

One survey pass produces, chunk by chunk, a :class:`PointRecords` (every detected return, with its
ground truth attached) and a :class:`DropoutRecords` (every pulse without a point, with its cause).
Both are frozen dataclasses of equal-length numpy arrays with a back-reference to the pulse
(``pulse_index``), never lists of per-point objects (DESIGN section 2).

Time is seconds from the start of the pass (DESIGN section 3). How that maps onto the LAS
``gps_time`` field is decided in :mod:`scanner_sim.io` and documented in ``docs/outputs.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Iterable, Mapping

import numpy as np

from muls.ranging import DROPOUT_CAUSES as MULS_DROPOUT_CAUSES

__all__ = [
    "DROPOUT_CAUSES",
    "DropoutRecords",
    "PointRecords",
    "dropout_cause_code",
]

#: Dropout cause names; a cause's index in this tuple is its code in ``DropoutRecords.cause``. The physics
#: decides them (muls.ranging): no_hit, blind_zone, below_threshold, saturated, masked_by_backscatter,
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
    """Shared behaviour of the struct-of-arrays record classes.

    Subclasses declare ``_SCHEMA``: field name -> (dtype, width or None) where width is the size
    of the second axis of a 2-D field.
    """

    _SCHEMA: ClassVar[Mapping[str, tuple[np.dtype, int | None]]] = {}

    def __post_init__(self) -> None:
        cls_name = type(self).__name__
        n = None
        first = None
        for name, (dtype, width) in self._SCHEMA.items():
            arr = _coerce_field(cls_name, name, getattr(self, name), np.dtype(dtype), width)
            object.__setattr__(self, name, arr)
            if n is None:
                n, first = arr.shape[0], name
            elif arr.shape[0] != n:
                raise ValueError(
                    f"{cls_name}.{name}: length {arr.shape[0]} differs from {first} "
                    f"(length {n}); every field must hold one entry per record"
                )

    def __len__(self) -> int:
        return int(getattr(self, next(iter(self._SCHEMA))).shape[0])

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of the record fields, in declaration order."""
        return tuple(cls._SCHEMA)

    @classmethod
    def empty(cls):
        """Records with zero entries and the right dtypes and shapes."""
        return cls(
            **{
                name: np.zeros((0,) if width is None else (0, width), dtype=dtype)
                for name, (dtype, width) in cls._SCHEMA.items()
            }
        )

    @classmethod
    def concatenate(cls, parts: Iterable):
        """Join records end to end (for example the chunks of a pass). An empty list gives ``empty()``."""
        parts = list(parts)
        for i, part in enumerate(parts):
            if not isinstance(part, cls):
                raise ValueError(
                    f"{cls.__name__}.concatenate: item {i} is a {type(part).__name__}, "
                    f"expected {cls.__name__}"
                )
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        return cls(
            **{name: np.concatenate([getattr(p, name) for p in parts]) for name in cls._SCHEMA}
        )

    def select(self, index):
        """Records at ``index`` (a boolean mask of length n, or integer indices)."""
        index = np.asarray(index)
        if index.dtype == bool and index.shape != (len(self),):
            raise ValueError(
                f"{type(self).__name__}.select: mask shape {index.shape} does not match "
                f"the {len(self)} records"
            )
        return type(self)(**{name: getattr(self, name)[index] for name in self._SCHEMA})

    def as_dict(self) -> dict[str, np.ndarray]:
        """Field name -> array (the arrays themselves, not copies)."""
        return {name: getattr(self, name) for name in self._SCHEMA}


@dataclass(frozen=True, eq=False)
class PointRecords(_Records):
    """Detected returns of a batch of pulses, one entry per point, with ground truth attached.

    Fields (n = number of points):

    - ``gps_time_s`` (n,) float64 [s]: emission time of the pulse, seconds from the pass start.
      Mapped onto LAS ``gps_time`` as Adjusted Standard GPS time plus a configurable offset
      (``scanner_sim.io.LasWriter``, ``docs/outputs.md``).
    - ``xyz`` (n, 3) float64 [m]: estimated point position in the world frame (x east, y north,
      z up), as the instrument and navigation would place it: ranging error and navigation noise included.
    - ``intensity`` (n,) uint16: LAS intensity (peak amplitude of the chosen channel, scaled; see docs).
    - ``return_number`` (n,) uint8: 1-based return number within its pulse (1..15).
    - ``number_of_returns`` (n,) uint8: returns detected for that pulse (1..15).
    - ``classification`` (n,) uint8: ground-truth class code of the surface hit
      (the scene label table, ``docs/scene-format.md``).
    - ``scan_angle_deg`` (n,) float32 [deg]: mirror angle of the pulse, 0 at nadir.
    - ``channel`` (n,) uint8: detection channel that ranged the point (1..3 for the MUL preset).
    - ``amplitude_lsb`` (n,) float32 [LSB]: peak amplitude above baseline in the chosen channel.
    - ``snr`` (n,) float32 [1]: peak amplitude over the channel's noise standard deviation.
    - ``saturated`` (n,) bool: the chosen channel's echo was clipped by the ADC.
    - ``true_range_m`` (n,) float32 [m]: range from the transmitter to the true hit on the mesh.
    - ``range_error_m`` (n,) float32 [m]: measured minus true range.
    - ``incidence_deg`` (n,) float32 [deg]: angle between the beam and the surface normal.
    - ``object_id`` (n,) int32: id of the scene object hit (-1 if none or unknown).
    - ``pulse_index`` (n,) int64: index of the pulse in the pass (back-reference).
    """

    gps_time_s: np.ndarray
    xyz: np.ndarray
    intensity: np.ndarray
    return_number: np.ndarray
    number_of_returns: np.ndarray
    classification: np.ndarray
    scan_angle_deg: np.ndarray
    channel: np.ndarray
    amplitude_lsb: np.ndarray
    snr: np.ndarray
    saturated: np.ndarray
    true_range_m: np.ndarray
    range_error_m: np.ndarray
    incidence_deg: np.ndarray
    object_id: np.ndarray
    pulse_index: np.ndarray

    _SCHEMA: ClassVar[Mapping[str, tuple[np.dtype, int | None]]] = {
        "gps_time_s": (np.dtype(np.float64), None),
        "xyz": (np.dtype(np.float64), 3),
        "intensity": (np.dtype(np.uint16), None),
        "return_number": (np.dtype(np.uint8), None),
        "number_of_returns": (np.dtype(np.uint8), None),
        "classification": (np.dtype(np.uint8), None),
        "scan_angle_deg": (np.dtype(np.float32), None),
        "channel": (np.dtype(np.uint8), None),
        "amplitude_lsb": (np.dtype(np.float32), None),
        "snr": (np.dtype(np.float32), None),
        "saturated": (np.dtype(np.bool_), None),
        "true_range_m": (np.dtype(np.float32), None),
        "range_error_m": (np.dtype(np.float32), None),
        "incidence_deg": (np.dtype(np.float32), None),
        "object_id": (np.dtype(np.int32), None),
        "pulse_index": (np.dtype(np.int64), None),
    }


@dataclass(frozen=True, eq=False)
class DropoutRecords(_Records):
    """Pulses that produced no point, one entry per pulse, with the cause.

    Fields (n = number of dropped pulses):

    - ``pulse_index`` (n,) int64: index of the pulse in the pass.
    - ``time_s`` (n,) float64 [s]: emission time, seconds from the pass start.
    - ``origin`` (n, 3) float64 [m]: transmitter position in the world frame.
    - ``direction`` (n, 3) float32 [1]: unit beam axis in the world frame.
    - ``cause`` (n,) uint8: index into :data:`DROPOUT_CAUSES`.
    """

    pulse_index: np.ndarray
    time_s: np.ndarray
    origin: np.ndarray
    direction: np.ndarray
    cause: np.ndarray

    CAUSES: ClassVar[tuple[str, ...]] = DROPOUT_CAUSES

    _SCHEMA: ClassVar[Mapping[str, tuple[np.dtype, int | None]]] = {
        "pulse_index": (np.dtype(np.int64), None),
        "time_s": (np.dtype(np.float64), None),
        "origin": (np.dtype(np.float64), 3),
        "direction": (np.dtype(np.float32), 3),
        "cause": (np.dtype(np.uint8), None),
    }

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
