"""points.las: :class:`PointRecords` as LAS 1.4, point data record format 6 plus extra dimensions, streamed.

The layout comes from the field declarations of :class:`~scanner_sim.records.point_records.PointRecords`: a
:class:`~scanner_sim.records.point_records.LasStandard` field fills standard dimensions through its conversion
(:data:`_TO_LAS`, :data:`_FROM_LAS`), a :class:`~scanner_sim.records.point_records.LasExtra` field is an extra
dimension (:data:`EXTRA_DIMENSIONS`). Header, VLRs and time mapping: ``docs/outputs.md``. Writer and reader stay in
one module, over the 450 lines aimed at, because both are built from the same field tables and conversions: split,
a change to a field's LAS form would have to be made in two places that must agree.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Mapping
from datetime import date, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import laspy
import numpy as np

from muls.infra.atomic import PathLike, StreamingWriter, atomic_path
from scanner_sim.io.summary import jsonable
from scanner_sim.records.point_records import LasExtra, LasStandard, PointRecords

__all__ = [
    "EXTRA_DIMENSIONS",
    "LAS_POINT_FORMAT",
    "LAS_SCALE_M",
    "LAS_VERSION",
    "LOCAL_ENGINEERING_WKT",
    "SCAN_ANGLE_UNIT_DEG",
    "LasWriter",
    "read_las",
    "read_las_metadata",
    "scan_angle_to_las",
    "write_las",
]

LAS_VERSION = "1.4"
LAS_POINT_FORMAT = 6
#: Default coordinate scale [m]: quantisation error at most 0.5 mm.
LAS_SCALE_M = 0.001
#: Unit of the point format 6 ``scan_angle`` field [deg] (LAS 1.4 R15: int16, 0.006 degree steps).
SCAN_ANGLE_UNIT_DEG = 0.006
#: Default CRS: a local engineering (Cartesian) frame in metres, the scene's world frame.
#: OGC WKT 1 (01-009), as LAS 1.4 R15 asks for the LASF_Projection / 2112 record.
LOCAL_ENGINEERING_WKT = (
    'LOCAL_CS["muls-scanner scene frame (x east, y north, z up)",'
    'LOCAL_DATUM["scene local origin",0],'
    'UNIT["metre",1],'
    'AXIS["X",EAST],AXIS["Y",NORTH],AXIS["Z",UP]]'
)

_COLUMNS = PointRecords.columns()
#: PointRecords fields in standard dimensions: field -> :class:`LasStandard`.
_STANDARD: dict[str, LasStandard] = {n: c.las for n, c in _COLUMNS.items() if isinstance(c.las, LasStandard)}
#: Standard dimensions that also carry a copy of a field (where it fits): field -> dimension.
_ALSO: dict[str, str] = {n: c.also for n, c in _COLUMNS.items() if c.also is not None}
#: Extra dimensions, in file order: PointRecords field -> (numpy dtype in the file, description <= 32 chars).
EXTRA_DIMENSIONS: dict[str, tuple[np.dtype, str]] = {
    n: (c.las.dtype, c.las.description) for n, c in _COLUMNS.items() if isinstance(c.las, LasExtra)
}

_METADATA_USER_ID = "muls-scanner"
_METADATA_RECORD_ID = 1
_GENERATING_SOFTWARE = "muls-scanner scanner_sim"
_SYSTEM_IDENTIFIER = "SIMULATION: MULS lidar"
_VLR_MAX_BYTES = 65535


#: The GPS time origin, and the GPS second that Adjusted Standard GPS time 0 stands for.
_GPS_EPOCH = datetime(1980, 1, 6, tzinfo=timezone.utc)
_ADJUSTED_GPS_ORIGIN_S = 1e9


def creation_date(gps_time_offset_s: float = 0.0) -> date:
    """The LAS header's creation date: a stamp from the pass, never the clock, so a seed gives the same
    bytes on any day. ``SOURCE_DATE_EPOCH`` (seconds since 1970-01-01 UTC, the reproducible-builds
    convention) when set; otherwise the UTC date the pass starts at, Adjusted Standard GPS time
    ``gps_time_offset_s`` (2011-09-14 for the default 0)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    try:
        if epoch is not None and epoch.strip():
            return datetime.fromtimestamp(int(epoch), timezone.utc).date()
        return (_GPS_EPOCH + timedelta(seconds=_ADJUSTED_GPS_ORIGIN_S + gps_time_offset_s)).date()
    except (ValueError, OverflowError, OSError):
        what = (f"SOURCE_DATE_EPOCH = {epoch!r}: must be whole seconds since 1970-01-01 UTC" if epoch is not None
                else f"gps_time_offset_s = {gps_time_offset_s!r}: puts the pass start outside the years 1 to 9999")
        raise ValueError(what) from None


def scan_angle_to_las(scan_angle_deg: np.ndarray) -> np.ndarray:
    """Scan angle (n,) [deg] to the LAS 1.4 format 6 ``scan_angle`` field, (n,) int16 in 0.006 deg units.

    Angles are first wrapped into [-180, 180) (a rotating mirror's 350 deg is -10 deg), so every
    value fits the field's +-30,000 range.
    """
    a = np.asarray(scan_angle_deg, dtype=np.float64)
    wrapped = (a + 180.0) % 360.0 - 180.0
    return np.clip(np.rint(wrapped / SCAN_ANGLE_UNIT_DEG), -30000, 30000).astype(np.int16)


def _scaled_counts(xyz_m: np.ndarray, writer: LasWriter) -> list[np.ndarray]:
    """X, Y, Z int32 counts of ``scale_m`` around ``offset_m`` for (n, 3) points [m]."""
    counts = np.rint((xyz_m - writer.offset_m) / writer.scale_m)
    lim = np.iinfo(np.int32)
    if counts.min() < lim.min or counts.max() > lim.max:
        raise ValueError(
            f"PointRecords.xyz: coordinates span {xyz_m.min(axis=0)}..{xyz_m.max(axis=0)} m, too far "
            f"from offset_m {writer.offset_m} for scale_m {writer.scale_m} (int32 counts); "
            "set offset_m to the scene's local origin"
        )
    return [c.astype(np.int32) for c in counts.T]


#: LasStandard.conversion -> (field values, writer) -> one array per LAS dimension.
_TO_LAS = {
    "copy": lambda values, writer: [values],
    "gps_time": lambda t_s, writer: [writer.gps_time_offset_s + t_s],
    "scaled": _scaled_counts,
    "scan_angle": lambda deg, writer: [scan_angle_to_las(deg)],
}

#: LasStandard.conversion -> (laspy LasData, dimension names, gps_time_offset_s [s]) -> field values.
#: laspy's lower-case x, y, z are the scaled coordinates [m] of the X, Y, Z counts.
_FROM_LAS = {
    "copy": lambda las, dims, t0_s: np.asarray(las[dims[0]]),
    "gps_time": lambda las, dims, t0_s: np.asarray(las[dims[0]], dtype=np.float64) - t0_s,
    "scaled": lambda las, dims, t0_s: np.column_stack([np.asarray(las[d.lower()]) for d in dims]),
    "scan_angle": lambda las, dims, t0_s: np.asarray(las[dims[0]], dtype=np.float64) * SCAN_ANGLE_UNIT_DEG,
}


def _as_triplet(name: str, value, *, positive: bool = False) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: {value!r} is not allowed; expected 3 finite numbers (x, y, z)")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name}: {value!r} is not allowed; every component must be > 0")
    return arr


def _check_range(name: str, values: np.ndarray, lo: int, hi: int) -> None:
    if values.size and (values.min() < lo or values.max() > hi):
        raise ValueError(
            f"PointRecords.{name}: values span [{values.min()}, {values.max()}]; LAS point format 6 "
            f"allows {lo}..{hi}"
        )


def _check_format_6(r: PointRecords) -> None:
    """Raise ValueError on values point format 6 cannot hold (return numbers, non-finite xyz or time)."""
    _check_range("return_number", r.return_number, 1, 15)
    _check_range("number_of_returns", r.number_of_returns, 1, 15)
    if np.any(r.return_number > r.number_of_returns):
        i = int(np.flatnonzero(r.return_number > r.number_of_returns)[0])
        raise ValueError(
            f"PointRecords.return_number: {int(r.return_number[i])} exceeds number_of_returns "
            f"{int(r.number_of_returns[i])} at point {i}"
        )
    if not np.all(np.isfinite(r.xyz)):
        raise ValueError("PointRecords.xyz: non-finite coordinates cannot be written to LAS")
    if not np.all(np.isfinite(r.gps_time_s)):
        raise ValueError("PointRecords.gps_time_s: non-finite times cannot be written to LAS")


def _set_extra_bytes_ranges(header: laspy.LasHeader, ranges: Mapping[str, tuple[float, float]]) -> None:
    """Write the true (min, max) of each extra dimension into the header's extra bytes descriptors.

    Works around laspy 2.7 (and its main branch): ``ExtraBytesStruct.grow`` indexes
    ``points[name][..., 0]`` on a 1-D field, so each descriptor's min/max is taken from the first
    point of each chunk, not from all points. laspy has no public way to set them
    (``ExtraBytesParams`` takes no range, ``ExtraBytesStruct.min``/``max`` are read-only), so this
    writes the descriptor's ctypes fields ``_min``/``_max``: the 8-byte type of the field's kind
    (uint64, int64 or double, LAS 1.4 R15 Table 24). A dimension without points gets its min/max bits
    cleared. ``tests/scanner_sim/io/test_io_las.py::test_laspy_extra_bytes_range_bug_still_present`` fails once laspy
    fixes ``grow``; then drop this function.
    """
    for struct_ in header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs:
        name = struct_.format_name()
        bits = struct_.MIN_BIT_MASK | struct_.MAX_BIT_MASK
        if name not in ranges:
            struct_.options &= ~bits
            continue
        long_type = {"u": "<u8", "i": "<i8", "f": "<f8"}[EXTRA_DIMENSIONS[name][0].kind]
        np.frombuffer(struct_._min, dtype=long_type)[:1] = ranges[name][0]
        np.frombuffer(struct_._max, dtype=long_type)[:1] = ranges[name][1]
        struct_.options |= bits


def _ranges_tracked_by_the_writer(points) -> None:
    """Stands in for laspy's ``ExtraBytesVlr.grow`` on a :class:`LasWriter`'s header: nothing to do."""


class LasWriter(StreamingWriter):
    """Streaming, atomic LAS 1.4 writer (point data record format 6 plus extra dimensions).

    Use as a context manager and call :meth:`write` once per chunk of points; memory does not grow
    with the pass (each chunk is packed and written, then dropped)::

        with LasWriter(out / "points.las", offset_m=scene_origin) as las:
            for chunk in chunks:
                las.write(chunk)

    The file appears under its final name only when the context exits without an exception
    (see :func:`~muls.infra.atomic.atomic_path`); on an exception it is discarded.

    Parameters
    ----------
    path : str or PathLike
        Destination ``.las`` (or ``.laz``, which needs a LAZ backend: ``pip install lazrs``).
    offset_m : float or (3,) float [m]
        Header offsets, the scene's local origin in world coordinates. Coordinates are stored as
        int32 counts of ``scale_m`` around it, so points must lie within about +-2,147 km of it.
    scale_m : float or (3,) float [m]
        Header scales, default 0.001 (millimetre resolution, quantisation error <= 0.5 mm).
    gps_time_offset_s : float [s]
        Adjusted Standard GPS time (GPS seconds minus 1e9) of the pass start: the LAS ``gps_time``
        of a point is ``gps_time_offset_s + gps_time_s``. The default 0 makes the LAS time equal
        seconds from pass start (the pass nominally starts at GPS second 1e9, 2011-09-14).
    crs_wkt : str or None
        OGC WKT (version 1) of the coordinate reference system; default
        :data:`LOCAL_ENGINEERING_WKT`. Written as the LASF_Projection/2112 VLR, with the global
        encoding WKT bit set (LAS 1.4 R15 requires WKT for formats 6-10).
    file_source_id : int
        Header file source id (0..65535), e.g. the survey leg of a file that holds one leg; each point's
        ``point_source_id`` is its own leg (``PointRecords.leg``).
    metadata : Mapping or None
        JSON-serialisable pass metadata (scene, water, seed...) stored in a ``muls-scanner``/1 VLR
        alongside the time offset, so :func:`read_las` can restore seconds from pass start.
    """

    def __init__(
        self,
        path: PathLike,
        *,
        offset_m=(0.0, 0.0, 0.0),
        scale_m=LAS_SCALE_M,
        gps_time_offset_s: float = 0.0,
        crs_wkt: str | None = None,
        file_source_id: int = 0,
        metadata: Mapping[str, Any] | None = None,
    ) -> None:
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in (".las", ".laz"):
            raise ValueError(f"LAS path {str(self.path)!r}: suffix {suffix!r} is not allowed; use .las or .laz")
        self._compress = suffix == ".laz"
        if self._compress and not laspy.LazBackend.detect_available():
            raise ValueError(
                f"LAS path {str(self.path)!r}: writing LAZ needs a LAZ backend, none is installed; "
                "pip install lazrs (or write .las)"
            )
        self.offset_m = _as_triplet("offset_m", offset_m)
        self.scale_m = _as_triplet("scale_m", scale_m, positive=True)
        if not math.isfinite(float(gps_time_offset_s)):
            raise ValueError(f"gps_time_offset_s: {gps_time_offset_s!r} is not allowed; expected a finite number")
        self.gps_time_offset_s = float(gps_time_offset_s)
        if not (isinstance(file_source_id, (int, np.integer)) and 0 <= int(file_source_id) <= 65535):
            raise ValueError(f"file_source_id: {file_source_id!r} is not allowed; expected an integer in 0..65535")
        self.file_source_id = int(file_source_id)
        wkt = LOCAL_ENGINEERING_WKT if crs_wkt is None else str(crs_wkt)
        if not wkt.strip():
            raise ValueError("crs_wkt: an empty string is not allowed; pass None for the local engineering CRS")
        self._header = self._make_header(wkt, metadata)
        self._atomic = None
        self._fh = None
        self._writer = None
        self._closed = False
        self.point_count = 0
        self._extra_range: dict[str, tuple[float, float]] = {}

    def _make_header(self, wkt: str, metadata: Mapping[str, Any] | None) -> laspy.LasHeader:
        header = laspy.LasHeader(version=LAS_VERSION, point_format=LAS_POINT_FORMAT)
        header.add_extra_dims(
            [laspy.ExtraBytesParams(name=name, type=dtype, description=desc)
             for name, (dtype, desc) in EXTRA_DIMENSIONS.items()]
        )
        header.offsets = self.offset_m
        header.scales = self.scale_m
        header.file_source_id = self.file_source_id
        header.system_identifier = _SYSTEM_IDENTIFIER
        header.generating_software = _GENERATING_SOFTWARE
        header.creation_date = creation_date(self.gps_time_offset_s)
        header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
        header.global_encoding.wkt = True
        header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(wkt))
        meta = {
            "gps_time_offset_s": self.gps_time_offset_s,
            "gps_time": "Adjusted Standard GPS time = gps_time_offset_s + seconds from pass start",
            "pass_metadata": dict(metadata) if metadata is not None else {},
        }
        payload = json.dumps(jsonable(meta), sort_keys=False).encode("utf-8")
        if len(payload) > _VLR_MAX_BYTES:
            raise ValueError(
                f"metadata: {len(payload)} bytes of JSON do not fit a LAS VLR (max {_VLR_MAX_BYTES}); "
                "keep it to settings and ids, and put large data in summary.json"
            )
        header.vlrs.append(
            laspy.VLR(user_id=_METADATA_USER_ID, record_id=_METADATA_RECORD_ID,
                      description="pass metadata (JSON)", record_data=payload)
        )
        return header

    def open(self) -> None:
        """Create the temporary file and write the header. Called by ``__enter__``."""
        if self._atomic is not None or self._closed:
            raise ValueError(f"LasWriter({str(self.path)!r}) is already open or closed")
        self._atomic = atomic_path(self.path)
        tmp = self._atomic.__enter__()
        try:
            self._fh = open(tmp, "w+b")  # noqa: SIM115 - closed in close() or _discard()
            self._writer = laspy.open(self._fh, mode="w", header=self._header, do_compress=self._compress,
                                      closefd=False)
            # The extra dimensions' ranges are this writer's own (_pack tracks them, close writes them): laspy's
            # per-chunk growth of them (see _set_extra_bytes_ranges) is overwritten, and cost as much as packing.
            for vlr in self._writer.header.vlrs.get("ExtraBytesVlr"):
                vlr.grow = _ranges_tracked_by_the_writer
        except BaseException as exc:
            self._discard(exc)
            raise

    def write(self, records: PointRecords) -> None:
        """Append one chunk of points. Raises ValueError on values LAS format 6 cannot hold."""
        name = type(self).__name__
        if not self._is_open():
            raise ValueError(f"{name}({str(self.path)!r}) is not open; use it as a context manager")
        if not isinstance(records, PointRecords):
            raise TypeError(f"{name}.write: expected PointRecords, got {type(records).__name__}")
        if len(records) == 0:
            return
        try:
            self._append(self._pack(records))
        except BaseException as exc:
            self._discard(exc)
            raise
        self.point_count += len(records)

    def _is_open(self) -> bool:
        return self._writer is not None

    def _append(self, packed) -> None:
        """Write one chunk's packed records (a laspy point record) where this writer keeps them."""
        self._writer.write_points(packed)

    def close(self) -> None:
        """Finish the header (counts, bounds), fsync, and move the file onto its final name."""
        if self._closed:
            return
        if self._writer is None:
            self.open()
        try:
            _set_extra_bytes_ranges(self._writer.header, self._extra_range)
            self._writer.close()
            self._fh.flush()
            self._fh.close()
        except BaseException as exc:
            self._discard(exc)
            raise
        atomic, self._atomic = self._atomic, None
        self._closed = True
        atomic.__exit__(None, None, None)

    def abort(self) -> None:
        """Discard the temporary file; the final path is left as it was."""
        self._discard(RuntimeError("LasWriter aborted"))

    def _discard(self, exc: BaseException) -> None:
        if self._fh is not None:
            with contextlib.suppress(Exception):
                self._fh.close()
        self._fh = None
        self._writer = None
        self._closed = True
        atomic, self._atomic = self._atomic, None
        if atomic is not None:
            with contextlib.suppress(BaseException):
                atomic.__exit__(type(exc), exc, exc.__traceback__)

    def _pack(self, r: PointRecords) -> laspy.ScaleAwarePointRecord:
        """One chunk as laspy point records; tracks each extra dimension's range."""
        _check_format_6(r)
        pts = laspy.ScaleAwarePointRecord.zeros(len(r), header=self._header)
        for name, std in _STANDARD.items():
            for dimension, values in zip(std.dimensions, _TO_LAS[std.conversion](getattr(r, name), self)):
                pts[dimension] = values
        for name, dimension in _ALSO.items():
            values = getattr(r, name)
            top = np.iinfo(pts[dimension].dtype).max if dimension != "scanner_channel" else 3  # a 2-bit field
            pts[dimension] = np.where(values <= top, values, 0)
        pts.synthetic = np.ones(len(r), np.uint8)  # simulated, not measured
        for name, (dtype, _) in EXTRA_DIMENSIONS.items():
            values = getattr(r, name).astype(dtype, copy=False)
            pts[name] = values
            if values.size == 0:
                continue
            # fmin/fmax pass over NaN (no surface): NaN only where every value is
            lo, hi = np.fmin.reduce(values).item(), np.fmax.reduce(values).item()
            if lo != lo:
                continue
            if name in self._extra_range:
                old_lo, old_hi = self._extra_range[name]
                lo, hi = min(lo, old_lo), max(hi, old_hi)
            self._extra_range[name] = (lo, hi)
        return pts


def write_las(path: PathLike, records: PointRecords, **kwargs) -> None:
    """Write all ``records`` to ``path`` in one go; keyword arguments as :class:`LasWriter`."""
    with LasWriter(path, **kwargs) as las:
        las.write(records)


def _metadata_from_header(header: laspy.LasHeader) -> dict:
    for vlr in header.vlrs:
        if vlr.user_id == _METADATA_USER_ID and vlr.record_id == _METADATA_RECORD_ID:
            return json.loads(bytes(vlr.record_data).decode("utf-8"))
    return {}


def read_las_metadata(path: PathLike) -> dict:
    """The ``muls-scanner`` metadata VLR of a LAS file as a dict (empty if absent)."""
    with laspy.open(path) as reader:
        return _metadata_from_header(reader.header)


def read_las(path: PathLike, *, gps_time_offset_s: float | None = None) -> PointRecords:
    """Read a LAS file written by :class:`LasWriter` back into :class:`PointRecords`.

    ``gps_time_s`` is LAS ``gps_time`` minus ``gps_time_offset_s`` [s] (default: the offset stored in
    the file's metadata VLR, 0 if there is none). A field the file does not carry (``pulse_index``,
    or the extra dimensions of a LAS from another tool) gets its declared unknown value (-1 for
    ``object_id`` and ``pulse_index``, else 0); points of one pulse share their ``gps_time``.
    Formats 0-5 give ``scan_angle_deg`` from their whole-degree ``scan_angle_rank``. A file that is not LAS/LAZ,
    or holds fewer points than its header promises (a copy cut short), raises ValueError naming it.
    """
    las = _read_whole(path)
    if gps_time_offset_s is None:
        gps_time_offset_s = float(_metadata_from_header(las.header).get("gps_time_offset_s", 0.0))
    n = len(las.points)
    names = set(las.point_format.dimension_names)
    fields = {}
    for name, col in _COLUMNS.items():
        if isinstance(col.las, LasStandard) and names.issuperset(col.las.dimensions):
            values = _FROM_LAS[col.las.conversion](las, col.las.dimensions, gps_time_offset_s)
        elif name == "scan_angle_deg" and "scan_angle_rank" in names:
            values = np.asarray(las.scan_angle_rank, dtype=np.float64)
        elif isinstance(col.las, LasExtra) and name in names:
            values = np.asarray(las[name])
        else:
            values = np.full((n,) if col.width is None else (n, col.width), col.unknown)
        fields[name] = values.astype(col.dtype)
    return PointRecords(**fields)


def _read_whole(path: PathLike) -> laspy.LasData:
    """``laspy.read(path)``, refused in one line naming the file (ValueError) when it is not LAS/LAZ or is cut short.

    laspy reads an uncompressed file cut short at a record's end as the points it holds, silently (a LAS of 300
    points cut at 10 kB reads as 133), and elsewhere with numpy's own message; lazrs reports compressed data that
    ends early as its own ``LazrsError``, and a LAZ cut inside its records' headers loses its LasZip VLR."""
    shown = os.fspath(path)
    try:
        with laspy.open(path) as reader:
            header = reader.header
    except laspy.LaspyException as exc:
        raise ValueError(f"{shown}: not a readable LAS/LAZ file ({' '.join(str(exc).split())})") from None
    promised = int(header.point_count)
    if not header.are_points_compressed:
        record = header.point_format.size
        held = max(0, os.path.getsize(path) - header.offset_to_point_data) // record
        if held < promised:
            raise ValueError(f"{shown}: truncated: its header promises {promised:,} points, the file holds "
                             f"{held:,} (a copy cut short?)")
    try:
        las = laspy.read(path)
    except (laspy.LaspyException, ValueError, RuntimeError) as exc:  # lazrs raises RuntimeError subclasses
        if isinstance(exc, RuntimeError) and "lazrs" not in type(exc).__module__.lower():
            raise
        what = ("the compressed points end early or are corrupt (a LAZ file cut short?: " if header.are_points_compressed
                else "not a readable LAS/LAZ file (")
        raise ValueError(f"{shown}: {what}{' '.join(str(exc).split())})") from None
    if len(las.points) < promised:
        raise ValueError(f"{shown}: truncated: its header promises {promised:,} points, the file holds "
                         f"{len(las.points):,} (a copy cut short?)")
    return las
