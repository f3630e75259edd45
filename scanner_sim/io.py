"""Writers and readers of a survey pass's output files (DESIGN section 6, ``docs/outputs.md``).

Every writer is atomic: it writes a hidden temporary file in the destination directory
(``.NAME.<random>.tmp``), flushes and fsyncs it, and renames it onto the final name with
``os.replace``. On any exception (KeyboardInterrupt included) the temporary file is removed and the
final name is left as it was: either absent or the previous complete file. A run killed outright can
leave a ``.*.tmp`` file behind, never a half-written file under a final name.

- :class:`LasWriter`, :func:`write_las`, :func:`read_las`: LAS 1.4, point data record format 6,
  with extra dimensions, streamed chunk by chunk.
- :class:`DropoutWriter`, :func:`write_dropouts_npz`, :func:`read_dropouts_npz`: dropped pulses.
- :func:`write_summary_json`, :func:`write_trajectory_csv` (+ :func:`read_trajectory_csv`),
  :func:`write_scene_ply` (+ :func:`read_scene_ply`), :func:`write_waveforms_npz`
  (+ :func:`read_waveforms_npz`), :func:`write_coverage_grid_npz` (+ :func:`read_coverage_grid_npz`),
  :func:`write_text`.
- :func:`atomic_path`: the context manager all of them use.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import secrets
import tempfile
from datetime import date
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from .records import DROPOUT_CAUSES, DropoutRecords, PointRecords

__all__ = [
    "EXTRA_DIMENSIONS",
    "LAS_POINT_FORMAT",
    "LAS_SCALE_M",
    "LAS_VERSION",
    "LOCAL_ENGINEERING_WKT",
    "SCAN_ANGLE_UNIT_DEG",
    "DropoutWriter",
    "LasWriter",
    "atomic_path",
    "read_coverage_grid_npz",
    "read_dropouts_npz",
    "read_las",
    "read_las_metadata",
    "read_scene_ply",
    "read_trajectory_csv",
    "read_waveforms_npz",
    "scan_angle_to_las",
    "write_coverage_grid_npz",
    "write_dropouts_npz",
    "write_las",
    "write_scene_ply",
    "write_summary_json",
    "write_text",
    "write_trajectory_csv",
    "write_waveforms_npz",
]

PathLike = str | os.PathLike

# --------------------------------------------------------------------------------------------
# Atomic files
# --------------------------------------------------------------------------------------------


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def _temp_name(final: Path) -> Path:
    return final.with_name(f".{final.name}.{secrets.token_hex(4)}.tmp")


@contextlib.contextmanager
def atomic_path(final_path: PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``final_path``; on success move it onto ``final_path``.

    The body writes the whole file to the yielded path (and closes it). On normal exit the file is
    fsynced and renamed onto ``final_path`` with ``os.replace`` (atomic on POSIX and Windows), then
    the directory is fsynced. If the body raises (any exception, KeyboardInterrupt included), the
    temporary file is removed, ``final_path`` is untouched and the exception propagates.

    The temporary name is hidden and ends in ``.tmp`` (``.points.las.1a2b3c4d.tmp``), so a run
    killed outright never leaves a file that looks complete.

    Raises ValueError if the parent directory of ``final_path`` does not exist or ``final_path`` is
    a directory.
    """
    final = Path(final_path)
    parent = final.parent if str(final.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(
            f"output path {str(final)!r}: directory {str(parent)!r} does not exist; create it first"
        )
    if final.is_dir():
        raise ValueError(f"output path {str(final)!r} is a directory; give a file name")
    tmp = _temp_name(final)
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"atomic_path: nothing was written to {tmp} for {final}")
        _fsync_path(tmp)
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    _fsync_dir(parent)


@contextlib.contextmanager
def _atomic_open(final_path: PathLike, mode: str = "wb", **kwargs) -> Iterator[Any]:
    """Open a temporary file for writing inside :func:`atomic_path`; yield the file object."""
    with atomic_path(final_path) as tmp:
        with open(tmp, mode, **kwargs) as fh:
            yield fh
            fh.flush()


# --------------------------------------------------------------------------------------------
# LAS 1.4
# --------------------------------------------------------------------------------------------

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

#: Extra dimensions of the LAS file: PointRecords field -> (numpy dtype, description <= 32 chars).
EXTRA_DIMENSIONS: dict[str, tuple[np.dtype, str]] = {
    "channel": (np.dtype(np.uint8), "detection channel (1..3)"),
    "amplitude_lsb": (np.dtype(np.float32), "peak amplitude [ADC LSB]"),
    "snr": (np.dtype(np.float32), "peak signal-to-noise ratio"),
    "saturated": (np.dtype(np.uint8), "1 if the ADC clipped the echo"),
    "true_range_m": (np.dtype(np.float32), "range to truth mesh [m]"),
    "range_error_m": (np.dtype(np.float32), "measured - true range [m]"),
    "incidence_deg": (np.dtype(np.float32), "incidence angle [deg]"),
    "object_id": (np.dtype(np.int32), "scene object id (-1 none)"),
}

_METADATA_USER_ID = "muls-scanner"
_METADATA_RECORD_ID = 1
_GENERATING_SOFTWARE = "muls-scanner scanner_sim"
_SYSTEM_IDENTIFIER = "SIMULATION: MULS lidar"
_VLR_MAX_BYTES = 65535


def _require_laspy():
    try:
        import laspy
    except ImportError as exc:  # pragma: no cover - laspy is a core dependency
        raise ImportError("writing LAS needs laspy: pip install laspy") from exc
    return laspy


def _as_triplet(name: str, value, *, positive: bool = False) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: {value!r} is not allowed; expected 3 finite numbers (x, y, z)")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name}: {value!r} is not allowed; every component must be > 0")
    return arr


class _StreamingWriter:
    """Context-manager protocol of the streaming writers: ``open`` on entry; ``close`` (the file appears
    complete) on a clean exit, ``abort`` (nothing appears) on an exception."""

    def __enter__(self):
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class LasWriter(_StreamingWriter):
    """Streaming, atomic LAS 1.4 writer (point data record format 6 plus extra dimensions).

    Use as a context manager and call :meth:`write` once per chunk of points; memory does not grow
    with the pass (each chunk is packed and written, then dropped)::

        with LasWriter(out / "points.las", offset_m=scene_origin) as las:
            for chunk in chunks:
                las.write(chunk)

    The file appears under its final name only when the context exits without an exception
    (see :func:`atomic_path`); on an exception it is discarded.

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
        Header file source id (0..65535), e.g. the survey line number; also written into every
        point's ``point_source_id``.
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
        laspy = _require_laspy()
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

        header = laspy.LasHeader(version=LAS_VERSION, point_format=LAS_POINT_FORMAT)
        header.add_extra_dims(
            [
                laspy.ExtraBytesParams(name=name, type=dtype, description=desc)
                for name, (dtype, desc) in EXTRA_DIMENSIONS.items()
            ]
        )
        header.offsets = self.offset_m
        header.scales = self.scale_m
        header.file_source_id = self.file_source_id
        header.system_identifier = _SYSTEM_IDENTIFIER
        header.generating_software = _GENERATING_SOFTWARE
        header.creation_date = date.today()
        header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
        header.global_encoding.wkt = True
        header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(wkt))
        meta = {
            "gps_time_offset_s": self.gps_time_offset_s,
            "gps_time": "Adjusted Standard GPS time = gps_time_offset_s + seconds from pass start",
            "pass_metadata": dict(metadata) if metadata is not None else {},
        }
        payload = json.dumps(_jsonable(meta), sort_keys=False).encode("utf-8")
        if len(payload) > _VLR_MAX_BYTES:
            raise ValueError(
                f"metadata: {len(payload)} bytes of JSON do not fit a LAS VLR (max {_VLR_MAX_BYTES}); "
                "keep it to settings and ids, and put large data in summary.json"
            )
        header.vlrs.append(
            laspy.VLR(
                user_id=_METADATA_USER_ID,
                record_id=_METADATA_RECORD_ID,
                description="pass metadata (JSON)",
                record_data=payload,
            )
        )
        self._header = header
        self._laspy = laspy
        self._atomic = None
        self._fh = None
        self._writer = None
        self._closed = False
        self.point_count = 0
        self._extra_range: dict[str, tuple[float, float]] = {}

    # -- context management -----------------------------------------------------------------
    def open(self) -> None:
        """Create the temporary file and write the header. Called by ``__enter__``."""
        if self._atomic is not None or self._closed:
            raise ValueError(f"LasWriter({str(self.path)!r}) is already open or closed")
        self._atomic = atomic_path(self.path)
        tmp = self._atomic.__enter__()
        try:
            self._fh = open(tmp, "w+b")
            self._writer = self._laspy.open(
                self._fh, mode="w", header=self._header, do_compress=self._compress, closefd=False
            )
        except BaseException as exc:
            self._discard(exc)
            raise

    def write(self, records: PointRecords) -> None:
        """Append one chunk of points. Raises ValueError on values LAS format 6 cannot hold."""
        if self._writer is None:
            raise ValueError(f"LasWriter({str(self.path)!r}) is not open; use it as a context manager")
        if not isinstance(records, PointRecords):
            raise ValueError(f"LasWriter.write: expected PointRecords, got {type(records).__name__}")
        if len(records) == 0:
            return
        try:
            packed = self._pack(records)
            self._writer.write_points(packed)
        except BaseException as exc:
            self._discard(exc)
            raise
        self.point_count += len(records)

    def close(self) -> None:
        """Finish the header (counts, bounds), fsync, and move the file onto its final name."""
        if self._closed:
            return
        if self._writer is None:
            self.open()
        try:
            self._set_extra_bytes_ranges()
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

    def _set_extra_bytes_ranges(self) -> None:
        """Write the true min and max of every extra dimension into the extra bytes VLR.

        laspy 2.7 sets the descriptors' min/max option bits but fills the values from the first
        point of each chunk (it indexes ``points[..., 0]`` on a 1-D field), which would make the
        file claim wrong ranges. LAS 1.4 R15 (Table 24) stores them as the 8-byte type of the
        field's kind (uint64, int64 or double). With no points, the min/max bits are cleared.
        """
        for vlr in self._writer.header.vlrs:
            if type(vlr).__name__ != "ExtraBytesVlr":
                continue
            for struct_ in vlr.extra_bytes_structs:
                name = bytes(struct_.name).rstrip(b"\0").decode()
                rng = self._extra_range.get(name)
                if rng is None:
                    struct_.options &= ~(struct_.MIN_BIT_MASK | struct_.MAX_BIT_MASK)
                    continue
                long_type = struct_._long_type()
                np.frombuffer(struct_._min, dtype=long_type)[:1] = rng[0]
                np.frombuffer(struct_._max, dtype=long_type)[:1] = rng[1]
                struct_.options |= struct_.MIN_BIT_MASK | struct_.MAX_BIT_MASK

    # -- packing ------------------------------------------------------------------------------
    def _pack(self, r: PointRecords):
        n = len(r)
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
        counts = np.rint((r.xyz - self.offset_m) / self.scale_m)
        lim = np.iinfo(np.int32)
        if counts.min() < lim.min or counts.max() > lim.max:
            raise ValueError(
                f"PointRecords.xyz: coordinates span {r.xyz.min(axis=0)}..{r.xyz.max(axis=0)} m, too far "
                f"from offset_m {self.offset_m} for scale_m {self.scale_m} (int32 counts); "
                "set offset_m to the scene's local origin"
            )
        if not np.all(np.isfinite(r.gps_time_s)):
            raise ValueError("PointRecords.gps_time_s: non-finite times cannot be written to LAS")

        pts = self._laspy.ScaleAwarePointRecord.zeros(n, header=self._header)
        pts.X = counts[:, 0].astype(np.int32)
        pts.Y = counts[:, 1].astype(np.int32)
        pts.Z = counts[:, 2].astype(np.int32)
        pts.intensity = r.intensity
        pts.return_number = r.return_number
        pts.number_of_returns = r.number_of_returns
        pts.classification = r.classification
        pts.scan_angle = scan_angle_to_las(r.scan_angle_deg)
        pts.point_source_id = np.full(n, self.file_source_id, dtype=np.uint16)
        pts.gps_time = self.gps_time_offset_s + r.gps_time_s
        for name, (dtype, _) in EXTRA_DIMENSIONS.items():
            values = getattr(r, name).astype(dtype, copy=False)
            pts[name] = values
            lo, hi = values.min().item(), values.max().item()
            if name in self._extra_range:
                old_lo, old_hi = self._extra_range[name]
                lo, hi = min(lo, old_lo), max(hi, old_hi)
            self._extra_range[name] = (lo, hi)
        return pts


def _check_range(name: str, values: np.ndarray, lo: int, hi: int) -> None:
    if values.size and (values.min() < lo or values.max() > hi):
        raise ValueError(
            f"PointRecords.{name}: values span [{values.min()}, {values.max()}]; LAS point format 6 "
            f"allows {lo}..{hi}"
        )


def scan_angle_to_las(scan_angle_deg: np.ndarray) -> np.ndarray:
    """Scan angle [deg] to the LAS 1.4 format 6 ``scan_angle`` field (int16, 0.006 deg units).

    Angles are first wrapped into [-180, 180) (a rotating mirror's 350 deg is -10 deg), so every
    value fits the field's +-30,000 range.
    """
    a = np.asarray(scan_angle_deg, dtype=np.float64)
    wrapped = (a + 180.0) % 360.0 - 180.0
    return np.clip(np.rint(wrapped / SCAN_ANGLE_UNIT_DEG), -30000, 30000).astype(np.int16)


def write_las(path: PathLike, records: PointRecords, **kwargs) -> None:
    """Write all ``records`` to ``path`` in one go; keyword arguments as :class:`LasWriter`."""
    with LasWriter(path, **kwargs) as las:
        las.write(records)


def read_las_metadata(path: PathLike) -> dict:
    """The ``muls-scanner`` metadata VLR of a LAS file as a dict (empty if absent)."""
    laspy = _require_laspy()
    with laspy.open(path) as reader:
        return _metadata_from_header(reader.header)


def _metadata_from_header(header) -> dict:
    for vlr in header.vlrs:
        if vlr.user_id == _METADATA_USER_ID and vlr.record_id == _METADATA_RECORD_ID:
            return json.loads(bytes(vlr.record_data).decode("utf-8"))
    return {}


def read_las(path: PathLike, *, gps_time_offset_s: float | None = None) -> PointRecords:
    """Read a LAS file written by :class:`LasWriter` back into :class:`PointRecords`.

    ``gps_time_s`` is LAS ``gps_time`` minus ``gps_time_offset_s`` (default: the offset stored in
    the file's metadata VLR, 0 if there is none). Extra dimensions missing from the file (a LAS from
    another tool) are filled with zeros (``object_id`` with -1) and ``pulse_index`` with -1:
    pulse indices are not stored in LAS, points of one pulse share their ``gps_time``.
    """
    laspy = _require_laspy()
    las = laspy.read(path)
    if gps_time_offset_s is None:
        gps_time_offset_s = float(_metadata_from_header(las.header).get("gps_time_offset_s", 0.0))
    n = len(las.points)
    names = set(las.point_format.dimension_names)
    if "scan_angle" in names:
        scan_deg = np.asarray(las.scan_angle, dtype=np.float64) * SCAN_ANGLE_UNIT_DEG
    else:  # formats 0-5: whole degrees
        scan_deg = np.asarray(las.scan_angle_rank, dtype=np.float64)
    gps = np.asarray(las.gps_time, dtype=np.float64) if "gps_time" in names else np.zeros(n)
    extra = {}
    for name, (dtype, _) in EXTRA_DIMENSIONS.items():
        if name in names:
            extra[name] = np.asarray(las[name]).astype(dtype)
        else:
            extra[name] = np.full(n, -1 if name == "object_id" else 0, dtype=dtype)
    return PointRecords(
        gps_time_s=gps - gps_time_offset_s,
        xyz=np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)]),
        intensity=np.asarray(las.intensity, dtype=np.uint16),
        return_number=np.asarray(las.return_number, dtype=np.uint8),
        number_of_returns=np.asarray(las.number_of_returns, dtype=np.uint8),
        classification=np.asarray(las.classification, dtype=np.uint8),
        scan_angle_deg=scan_deg.astype(np.float32),
        channel=extra["channel"],
        amplitude_lsb=extra["amplitude_lsb"],
        snr=extra["snr"],
        saturated=extra["saturated"].astype(bool),
        true_range_m=extra["true_range_m"],
        range_error_m=extra["range_error_m"],
        incidence_deg=extra["incidence_deg"],
        object_id=extra["object_id"],
        pulse_index=np.full(n, -1, dtype=np.int64),
    )


# --------------------------------------------------------------------------------------------
# Dropouts
# --------------------------------------------------------------------------------------------


def write_dropouts_npz(path: PathLike, records: DropoutRecords) -> None:
    """Write dropouts to a compressed ``.npz``, atomically.

    Arrays: ``pulse_index`` (n,) int64, ``time_s`` (n,) float64 [s], ``origin`` (n, 3) float64 [m],
    ``direction`` (n, 3) float32, ``cause`` (n,) uint8 and ``cause_names`` (6,) str (the code
    table, index = code). Read back with :func:`read_dropouts_npz`.
    """
    if not isinstance(records, DropoutRecords):
        raise ValueError(f"write_dropouts_npz: expected DropoutRecords, got {type(records).__name__}")
    with _atomic_open(path) as fh:
        np.savez_compressed(fh, cause_names=np.array(DROPOUT_CAUSES), **records.as_dict())


def read_dropouts_npz(path: PathLike) -> DropoutRecords:
    """Read a dropouts ``.npz`` back; causes are re-mapped by name if the stored table differs."""
    with np.load(path, allow_pickle=False) as z:
        cause = z["cause"]
        names = [str(s) for s in z["cause_names"]]
        if tuple(names) != DROPOUT_CAUSES:
            lut = np.array([DROPOUT_CAUSES.index(s) if s in DROPOUT_CAUSES else 255 for s in names], dtype=np.uint8)
            cause = lut[cause]
        return DropoutRecords(
            pulse_index=z["pulse_index"],
            time_s=z["time_s"],
            origin=z["origin"],
            direction=z["direction"],
            cause=cause,
        )


class DropoutWriter(_StreamingWriter):
    """Streaming, atomic dropouts writer with memory flat in the length of the pass.

    Each :meth:`write` appends the chunk's fields to raw spool files beside the destination
    (hidden ``.tmp`` files); :meth:`close` memory-maps them into the compressed ``.npz`` (numpy
    streams them into the archive in buffered blocks), renames it into place and removes the spool.
    On an exception inside the ``with`` block everything temporary is removed and no final file
    appears. The result is the same file as :func:`write_dropouts_npz` of all chunks concatenated.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)
        parent = self.path.parent if str(self.path.parent) else Path(".")
        if not parent.is_dir():
            raise ValueError(f"output path {str(self.path)!r}: directory {str(parent)!r} does not exist")
        self._spool: dict[str, tuple[Path, Any]] | None = None
        self._dir = parent
        self.count = 0
        self._counts = np.zeros(len(DROPOUT_CAUSES), dtype=np.int64)
        self._closed = False

    def open(self) -> None:
        """Start the spool. Called by ``__enter__``."""
        if self._spool is not None or self._closed:
            raise ValueError(f"DropoutWriter({str(self.path)!r}) is already open or closed")
        self._spool = {}
        try:
            for name in DropoutRecords.field_names():
                fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.{name}.", suffix=".tmp", dir=self._dir)
                self._spool[name] = (Path(tmp), os.fdopen(fd, "wb"))
        except BaseException:
            self.abort()
            raise

    def write(self, records: DropoutRecords) -> None:
        """Append one chunk of dropouts."""
        if self._spool is None:
            self.open()
        if not isinstance(records, DropoutRecords):
            raise ValueError(f"DropoutWriter.write: expected DropoutRecords, got {type(records).__name__}")
        try:
            for name, (_, fh) in self._spool.items():
                fh.write(getattr(records, name).tobytes())
        except BaseException:
            self.abort()
            raise
        self.count += len(records)
        self._counts += np.bincount(records.cause, minlength=len(DROPOUT_CAUSES))

    def counts_by_cause(self) -> dict[str, int]:
        """Dropouts written so far, per cause name (all causes present)."""
        return {name: int(self._counts[i]) for i, name in enumerate(DROPOUT_CAUSES)}

    def close(self) -> None:
        """Build the ``.npz`` from the spool, move it into place, remove the spool."""
        if self._closed:
            return
        if self._spool is None:
            self.open()
        try:
            arrays = {}
            for name, (tmp, fh) in self._spool.items():
                fh.close()
                dtype, width = DropoutRecords._SCHEMA[name]
                shape = (self.count,) if width is None else (self.count, width)
                if self.count:
                    arrays[name] = np.memmap(tmp, dtype=dtype, mode="r", shape=shape)
                else:
                    arrays[name] = np.zeros(shape, dtype=dtype)
            with _atomic_open(self.path) as out:
                np.savez_compressed(out, cause_names=np.array(DROPOUT_CAUSES), **arrays)
            del arrays
        finally:
            self._remove_spool()
            self._closed = True

    def abort(self) -> None:
        """Remove the spool; no final file is written."""
        self._remove_spool()
        self._closed = True

    def _remove_spool(self) -> None:
        for tmp, fh in (self._spool or {}).values():
            with contextlib.suppress(Exception):
                fh.close()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        self._spool = None


# --------------------------------------------------------------------------------------------
# summary.json
# --------------------------------------------------------------------------------------------


def _jsonable(obj):
    """Convert numpy scalars/arrays, paths, tuples, sets and dataclasses to JSON types.

    Non-finite floats (NaN, +-inf) become ``null``: JSON has no such numbers, and a ``NaN`` token
    breaks strict readers. Unknown objects raise ValueError naming their type.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, np.integer)) and not isinstance(obj, bool):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (set, frozenset)):
        return [_jsonable(v) for v in sorted(obj)]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return _jsonable(dataclasses.asdict(obj))
    raise ValueError(f"summary value of type {type(obj).__name__} is not JSON-serialisable: {obj!r}")


def write_summary_json(path: PathLike, summary: Mapping[str, Any]) -> None:
    """Write ``summary`` as JSON (indent 2, keys in insertion order, UTF-8), atomically.

    numpy scalars and arrays, tuples, paths and dataclasses are converted; NaN and infinities
    become ``null``.
    """
    if not isinstance(summary, Mapping):
        raise ValueError(f"write_summary_json: expected a mapping, got {type(summary).__name__}")
    text = json.dumps(_jsonable(summary), indent=2, sort_keys=False, ensure_ascii=False, allow_nan=False)
    with _atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text + "\n")


# --------------------------------------------------------------------------------------------
# trajectory.csv
# --------------------------------------------------------------------------------------------

_ATTITUDE_COLUMNS = {
    "rpy_deg": ("roll_deg", "pitch_deg", "yaw_deg"),
    "quaternion": ("qw", "qx", "qy", "qz"),
}


def _check_2d(name: str, arr, n: int, width: int, dtype=np.float64) -> np.ndarray:
    a = np.asarray(arr, dtype=dtype)
    if a.shape != (n, width):
        raise ValueError(f"{name}: shape {a.shape} is not allowed; expected ({n}, {width})")
    return a


def write_trajectory_csv(
    path: PathLike,
    time_s,
    position_m,
    attitude,
    *,
    attitude_format: str = "rpy_deg",
    estimated_position_m=None,
    estimated_attitude=None,
) -> None:
    """Write platform poses as CSV with one header line, atomically.

    Parameters
    ----------
    time_s : (n,) float [s]
        Seconds from the pass start.
    position_m : (n, 3) float [m]
        True platform position in the world frame (x east, y north, z up).
    attitude : (n, 3) or (n, 4) float
        True attitude: ``attitude_format="rpy_deg"`` gives roll, pitch, yaw [deg] (platform frame
        x forward, y left, z up; yaw counter-clockwise from east); ``"quaternion"`` gives the
        platform-to-world rotation as (qw, qx, qy, qz), scalar first.
    estimated_position_m, estimated_attitude : same shapes, optional
        The navigation solution (true pose plus navigation noise), written as ``est_*`` columns.

    Columns: ``time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg`` (or ``qw,qx,qy,qz``), then
    ``est_x_m,...`` when given. Times are written with ``%.9f`` (ns), positions with ``%.6f``
    (micrometres), attitudes with ``%.9g``.
    """
    if attitude_format not in _ATTITUDE_COLUMNS:
        raise ValueError(
            f"attitude_format: {attitude_format!r} is not allowed; expected one of {sorted(_ATTITUDE_COLUMNS)}"
        )
    t = np.asarray(time_s, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"time_s: shape {t.shape} is not allowed; expected (n,)")
    n = t.shape[0]
    att_cols = _ATTITUDE_COLUMNS[attitude_format]
    cols = ["time_s", "x_m", "y_m", "z_m", *att_cols]
    blocks = [t[:, None], _check_2d("position_m", position_m, n, 3), _check_2d("attitude", attitude, n, len(att_cols))]
    fmts = ["%.9f", "%.6f", "%.6f", "%.6f"] + ["%.9g"] * len(att_cols)
    if (estimated_position_m is None) != (estimated_attitude is None):
        raise ValueError("estimated_position_m and estimated_attitude: give both or neither")
    if estimated_position_m is not None:
        cols += ["est_x_m", "est_y_m", "est_z_m", *(f"est_{c}" for c in att_cols)]
        blocks += [
            _check_2d("estimated_position_m", estimated_position_m, n, 3),
            _check_2d("estimated_attitude", estimated_attitude, n, len(att_cols)),
        ]
        fmts += ["%.6f"] * 3 + ["%.9g"] * len(att_cols)
    table = np.hstack(blocks)
    with _atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        np.savetxt(fh, table, delimiter=",", header=",".join(cols), comments="", fmt=fmts)


def read_trajectory_csv(path: PathLike) -> dict[str, np.ndarray]:
    """Read a trajectory CSV: column name -> (n,) float64 array."""
    with open(path, encoding="utf-8") as fh:
        names = fh.readline().strip().split(",")
        data = np.loadtxt(fh, delimiter=",", ndmin=2)
    if data.size == 0:
        data = np.zeros((0, len(names)))
    return {name: data[:, i] for i, name in enumerate(names)}


# --------------------------------------------------------------------------------------------
# scene.ply
# --------------------------------------------------------------------------------------------


def write_scene_ply(path: PathLike, vertices, faces, face_label, face_object_id) -> None:
    """Write the truth meshes as one labelled binary PLY, atomically.

    Parameters
    ----------
    vertices : (n_vertices, 3) float [m]
        World coordinates; stored as ``double`` x, y, z (no float32 rounding of world coordinates).
    faces : (n_faces, 3) int
        Vertex indices of each triangle.
    face_label : (n_faces,) int
        Ground-truth class code per face (0..255, the scene label table), PLY ``uchar label``.
    face_object_id : (n_faces,) int
        Scene object id per face, PLY ``int object_id``.

    The file is ``binary_little_endian 1.0`` with ``element face`` properties
    ``list uchar int vertex_indices``, ``uchar label``, ``int object_id``: trimesh, Open3D (geometry
    only), CloudCompare and MeshLab read it; ``trimesh.load(path, process=False)`` keeps the labels in
    ``mesh.metadata["_ply_raw"]["face"]["data"]["label"]`` (and ``"object_id"``).
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices: shape {v.shape} is not allowed; expected (n_vertices, 3)")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and f.dtype.kind not in "iu"):
        raise ValueError(f"faces: shape {f.shape} dtype {f.dtype} is not allowed; expected (n_faces, 3) integers")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces: indices span [{f.min()}, {f.max()}], outside 0..{len(v) - 1}")
    labels = np.asarray(face_label)
    if labels.shape != (len(f),):
        raise ValueError(f"face_label: shape {labels.shape} is not allowed; expected ({len(f)},)")
    if labels.size and (labels.min() < 0 or labels.max() > 255):
        raise ValueError(f"face_label: values span [{labels.min()}, {labels.max()}], allowed 0..255")
    oid = np.asarray(face_object_id)
    if oid.shape != (len(f),):
        raise ValueError(f"face_object_id: shape {oid.shape} is not allowed; expected ({len(f)},)")
    info = np.iinfo(np.int32)
    if oid.size and (oid.min() < info.min or oid.max() > info.max):
        raise ValueError("face_object_id: values do not fit int32")

    header = (
        "ply\n"
        "format binary_little_endian 1.0\n"
        "comment muls-scanner truth scene; label = class code (docs/scene-format.md)\n"
        f"element vertex {len(v)}\n"
        "property double x\nproperty double y\nproperty double z\n"
        f"element face {len(f)}\n"
        "property list uchar int vertex_indices\n"
        "property uchar label\n"
        "property int object_id\n"
        "end_header\n"
    ).encode("ascii")
    vrec = np.ascontiguousarray(v.astype("<f8"))
    frec = np.zeros(len(f), dtype=[("count", "u1"), ("index", "<i4", (3,)), ("label", "u1"), ("object_id", "<i4")])
    frec["count"] = 3
    frec["index"] = f
    frec["label"] = labels
    frec["object_id"] = oid
    with _atomic_open(path) as fh:
        fh.write(header)
        fh.write(vrec.tobytes())
        fh.write(frec.tobytes())


def read_scene_ply(path: PathLike) -> dict[str, np.ndarray]:
    """Read a PLY written by :func:`write_scene_ply`: ``vertices``, ``faces``, ``face_label``, ``face_object_id``."""
    with open(path, "rb") as fh:
        lines = []
        while True:
            line = fh.readline()
            if not line:
                raise ValueError(f"{path}: no end_header; not a PLY written by write_scene_ply")
            lines.append(line.decode("ascii").strip())
            if lines[-1] == "end_header":
                break
        counts = {ln.split()[1]: int(ln.split()[2]) for ln in lines if ln.startswith("element")}
        if "format binary_little_endian 1.0" not in lines or "property uchar label" not in lines:
            raise ValueError(f"{path}: not a labelled binary PLY written by write_scene_ply")
        nv, nf = counts.get("vertex", 0), counts.get("face", 0)
        v = np.frombuffer(fh.read(nv * 24), dtype="<f8").reshape(nv, 3)
        frec = np.frombuffer(
            fh.read(nf * 18),
            dtype=[("count", "u1"), ("index", "<i4", (3,)), ("label", "u1"), ("object_id", "<i4")],
        )
    return {
        "vertices": v.astype(np.float64),
        "faces": frec["index"].astype(np.int64),
        "face_label": frec["label"].astype(np.uint8),
        "face_object_id": frec["object_id"].astype(np.int32),
    }


# --------------------------------------------------------------------------------------------
# waveforms.npz
# --------------------------------------------------------------------------------------------

_WAVEFORM_RESERVED = {"pulse_index", "time_ns", "channel_names"}


def write_waveforms_npz(path: PathLike, pulse_index, time_ns, channels: Mapping[str, np.ndarray]) -> None:
    """Write digitised waveforms of selected pulses to a compressed ``.npz``, atomically.

    Parameters
    ----------
    pulse_index : (n_pulses,) int
        Pulse of each record.
    time_ns : (n_samples,) or (n_pulses, n_samples) float [ns]
        Sample times from emission (one grid for all, or one per pulse when the sampling phase is
        random per pulse).
    channels : dict name -> (n_pulses, n_samples) array
        One array per channel, e.g. ``{"ch0": ..., "ch1": ..., "ch2": ..., "ch3": ...}`` in ADC
        LSB (dtype kept as given). Names must be identifiers and not ``pulse_index``, ``time_ns``
        or ``channel_names``.

    Arrays stored: ``pulse_index``, ``time_ns``, ``channel_names`` (str, in the given order) and
    one array per channel under its name.
    """
    pi = np.asarray(pulse_index)
    if pi.ndim != 1 or (pi.size and pi.dtype.kind not in "iu"):
        raise ValueError(f"pulse_index: shape {pi.shape} dtype {pi.dtype} is not allowed; expected (n_pulses,) integers")
    pi = pi.astype(np.int64)
    n = pi.shape[0]
    t = np.asarray(time_ns, dtype=np.float64)
    if t.ndim not in (1, 2) or (t.ndim == 2 and t.shape[0] != n):
        raise ValueError(f"time_ns: shape {t.shape} is not allowed; expected (n_samples,) or ({n}, n_samples)")
    n_samples = t.shape[-1]
    if not isinstance(channels, Mapping) or not channels:
        raise ValueError("channels: expected a non-empty dict of name -> (n_pulses, n_samples) array")
    arrays = {}
    for name, data in channels.items():
        if not (isinstance(name, str) and name.isidentifier()) or name in _WAVEFORM_RESERVED:
            raise ValueError(
                f"channels: name {name!r} is not allowed; use an identifier other than {sorted(_WAVEFORM_RESERVED)}"
            )
        a = np.asarray(data)
        if a.shape != (n, n_samples):
            raise ValueError(f"channels[{name!r}]: shape {a.shape} is not allowed; expected ({n}, {n_samples})")
        arrays[name] = a
    with _atomic_open(path) as fh:
        np.savez_compressed(
            fh, pulse_index=pi, time_ns=t, channel_names=np.array(list(arrays)), **arrays
        )


def read_waveforms_npz(path: PathLike) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Read ``(pulse_index, time_ns, channels)`` back from :func:`write_waveforms_npz` output."""
    with np.load(path, allow_pickle=False) as z:
        names = [str(s) for s in z["channel_names"]]
        return z["pulse_index"], z["time_ns"], {name: z[name] for name in names}


# --------------------------------------------------------------------------------------------
# coverage_grid.npz, text files
# --------------------------------------------------------------------------------------------


def write_coverage_grid_npz(path: PathLike, grid, state, reaching, valid) -> None:
    """Write a pass's plan-cell coverage to a compressed ``.npz``, atomically.

    ``grid`` is a :class:`scanner_sim.coverage.PlanGrid`; ``state`` (ny, nx) int16 (-2 not reached,
    -1 covered, else an index into ``gap_cause_names``); ``reaching`` and ``valid`` (ny * nx,) or
    (ny, nx) counts of reaching pulses and valid points per cell. Row = y, column = x; cell (0, 0) has its
    lower-left corner at ``origin_m``.
    """
    from .coverage import GAP_CAUSES

    shape = tuple(grid.shape)
    arrays = {"state": np.asarray(state, np.int16), "reaching": np.asarray(reaching, np.int64),
              "valid": np.asarray(valid, np.int64)}
    for name, a in arrays.items():
        if a.size != shape[0] * shape[1]:
            raise ValueError(f"{name}: {a.size} cells is not allowed; the grid has {shape[0]} x {shape[1]}")
        arrays[name] = a.reshape(shape)
    with _atomic_open(path) as fh:
        np.savez_compressed(fh, origin_m=np.asarray(grid.origin_m, float), cell_m=np.float64(grid.cell_m),
                            gap_cause_names=np.array(GAP_CAUSES), **arrays)


def read_coverage_grid_npz(path: PathLike) -> dict[str, np.ndarray]:
    """The arrays of :func:`write_coverage_grid_npz` output, by name."""
    with np.load(path, allow_pickle=False) as z:
        return {name: z[name] for name in z.files}


def write_text(path: PathLike, text: str) -> None:
    """Write UTF-8 text (Markdown, HTML) atomically."""
    with _atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
