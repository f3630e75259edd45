"""points.copc.laz: the LAS points as a Cloud-Optimised Point Cloud (COPC 1.0), written through copclib.

COPC is LAZ 1.4 whose points are grouped in the nodes of an octree, each node compressed on its own, so that a
viewer (Potree, QGIS) or a reader (laspy's ``CopcReader``, PDAL) fetches only the nodes a view or a bounds
query needs, coarse levels first. The header, the extra dimensions (``thu_m``, ``tvu_m``...), the CRS record
and the point packing are those of :class:`~scanner_sim.io.las.LasWriter`: :class:`CopcWriter` is one, storing
its packed records in a spill file beside the output until it closes and builds the octree.

The octree (:func:`octree_levels`): the root is the cube around the points; at each depth every node keeps the
first point (in pass order) of each of the ``GRID_CELLS``\\ :sup:`3` cells it spans and sends the rest to its
eight children, and a node of at most ``max_node_points`` remaining points keeps them all (a leaf). So each
level is an even thinning of the cloud, as COPC viewers expect, and every point lies in exactly one node.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import laspy
import numpy as np

from muls.infra.atomic import atomic_path
from scanner_sim.io.las import LasWriter, _set_extra_bytes_ranges
from scanner_sim.records.point_records import PointRecords

__all__ = ["GRID_CELLS", "MAX_NODE_POINTS", "CopcWriter", "octree_levels", "write_copc"]

#: Cells a side of a node's sampling grid: a node keeps at most GRID_CELLS**3 points (the COPC ``spacing`` is the
#: root cube's side over this). 128 is the grid of PDAL's and untwine's COPC writers.
GRID_CELLS = 128
#: A node with at most this many points left keeps them all (a leaf); bounds a node's decompressed size.
MAX_NODE_POINTS = 100_000
#: Deepest level: past it a node keeps every remaining point (points repeated at one spot never thin out).
MAX_DEPTH = 20


def octree_levels(xyz: np.ndarray, max_node_points: int = MAX_NODE_POINTS):
    """The COPC octree of points ``xyz`` (n, 3) [m].

    Returns (centre (3,) [m], halfsize [m], keys (n, 4) int32 of each point's node ``(depth, x, y, z)``). The
    cube is the points' bounding box made cubic and widened by one part in 10^6, so every point lies strictly
    inside; node (d, x, y, z) spans ``centre - halfsize + (x, y, z) * 2 * halfsize / 2**d`` plus one step."""
    xyz = np.asarray(xyz, np.float64)
    n = len(xyz)
    keys = np.zeros((n, 4), np.int32)
    if n == 0:
        return np.zeros(3), 1.0, keys
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    centre = (lo + hi) / 2.0
    halfsize = max(float((hi - lo).max()) / 2.0, 0.5) * (1.0 + 1e-6)
    rel = (xyz - (centre - halfsize)) / (2.0 * halfsize)  # in [0, 1)
    left = np.arange(n)
    for depth in range(MAX_DEPTH + 1):
        fine = np.minimum((rel[left] * (GRID_CELLS << depth)).astype(np.int64), (GRID_CELLS << depth) - 1)
        node = fine // GRID_CELLS
        keys[left, 0], keys[left, 1:] = depth, node
        if depth == MAX_DEPTH:
            break
        _, node_of, node_size = np.unique(_cell_keys(node, depth), return_inverse=True, return_counts=True)
        leaf = node_size[node_of.ravel()] <= max_node_points
        # the first point of each occupied cell (np.unique's index is the first occurrence)
        _, first = np.unique(_cell_keys(fine, depth + GRID_CELLS.bit_length() - 1), return_index=True)
        stays = leaf.copy()
        stays[first] = True
        left = left[~stays]
        if left.size == 0:
            break
    return centre, halfsize, keys


def _cell_keys(cells: np.ndarray, bits: int) -> np.ndarray:
    """One sortable key per row of ``cells`` (n, 3) int64, each coordinate below 2**bits: an int64 while three
    coordinates fit its 63 bits (a 1-D sort, several times faster than ``np.unique(axis=0)``), else the rows."""
    if 3 * bits <= 63:
        return (cells[:, 0] << (2 * bits)) | (cells[:, 1] << bits) | cells[:, 2]
    return np.ascontiguousarray(cells).view([("x", np.int64), ("y", np.int64), ("z", np.int64)]).ravel()


class CopcWriter(LasWriter):
    """Streaming, atomic writer of points.copc.laz: :class:`~scanner_sim.io.las.LasWriter`'s header and point
    records, organised as a COPC octree when it closes (parameters as LasWriter's; the path must end in
    ``.copc.laz``; ``max_node_points`` as :func:`octree_levels`).

    The packed records wait in a hidden spill file beside the output (the size of an uncompressed LAS), so
    memory does not grow with the pass until :meth:`close` reads their coordinates back (24 bytes a point)."""

    def __init__(self, path, *, max_node_points: int = MAX_NODE_POINTS, **kwargs) -> None:
        if not str(path).lower().endswith(".copc.laz"):
            raise ValueError(f"COPC path {str(path)!r}: must end in .copc.laz")
        super().__init__(path, **kwargs)
        self.max_node_points = int(max_node_points)
        self._spill = None

    def open(self) -> None:
        if self._atomic is not None or self._closed:
            raise ValueError(f"CopcWriter({str(self.path)!r}) is already open or closed")
        self._atomic = atomic_path(self.path)
        self._tmp = self._atomic.__enter__()
        try:
            self._spill = open(self._tmp.with_suffix(".records"), "w+b")  # noqa: SIM115 - closed in close() or abort()
        except BaseException as exc:
            self._discard(exc)
            raise

    def _is_open(self) -> bool:
        return self._spill is not None

    def _append(self, packed) -> None:
        self._spill.write(packed.array.tobytes())

    def close(self) -> None:
        """Build the octree, write every node through copclib, and move the file onto its final name."""
        if self._closed:
            return
        if self._spill is None:
            self.open()
        try:
            self._spill.flush()
            self._write_copc(self._tmp)
        except BaseException as exc:
            self._discard(exc)
            raise
        self._close_spill()
        atomic, self._atomic = self._atomic, None
        self._closed = True
        atomic.__exit__(None, None, None)

    def _discard(self, exc: BaseException) -> None:
        self._close_spill()
        super()._discard(exc)

    def _close_spill(self) -> None:
        if self._spill is not None:
            with contextlib.suppress(OSError):
                self._spill.close()
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self._spill.name)
        self._spill = None

    def _write_copc(self, tmp: Path) -> None:
        import copclib

        header = self._header
        dtype = header.point_format.dtype()
        records = (np.memmap(self._spill.name, dtype=dtype, mode="r") if self.point_count
                   else np.zeros(0, dtype))
        counts = np.column_stack([records["X"], records["Y"], records["Z"]]).astype(np.float64)
        xyz = counts * self.scale_m + self.offset_m
        centre, halfsize, keys = octree_levels(xyz, self.max_node_points)
        _set_extra_bytes_ranges(header, self._extra_range)
        config = copclib.CopcConfigWriter(
            header.point_format.id, copclib.Vector3(*self.scale_m), copclib.Vector3(*self.offset_m),
            header.vlrs.get("WktCoordinateSystemVlr")[0].string, _copclib_extra_bytes(header), False)
        writer = copclib.FileWriter(str(tmp), config)
        try:
            las = writer.copc_config.las_header
            las.file_source_id = self.file_source_id
            las.system_identifier = header.system_identifier
            las.generating_software = header.generating_software
            las.creation_day = header.creation_date.timetuple().tm_yday
            las.creation_year = header.creation_date.year
            las.SetGpsTimeBit()
            if len(xyz):
                las.min = copclib.Vector3(*xyz.min(axis=0))
                las.max = copclib.Vector3(*xyz.max(axis=0))
                las.points_by_return = np.bincount(records["bit_fields"] & 0x0F, minlength=16)[1:16].tolist()
            info = writer.copc_config.copc_info
            info.center_x, info.center_y, info.center_z = (float(c) for c in centre)
            info.halfsize = halfsize
            info.spacing = 2.0 * halfsize / GRID_CELLS
            order = np.lexsort((keys[:, 3], keys[:, 2], keys[:, 1], keys[:, 0]))
            sorted_keys = keys[order]
            starts = np.flatnonzero(np.r_[len(order) > 0, np.any(sorted_keys[1:] != sorted_keys[:-1], axis=1)])
            for start, stop in zip(starts, np.r_[starts[1:], len(order)]):
                rows = order[start:stop]  # lexsort is stable: pass order inside a node
                writer.AddNode(copclib.VoxelKey(*(int(k) for k in sorted_keys[start])),
                               copclib.VectorChar(np.ascontiguousarray(records[rows]).view(np.int8)))
        finally:
            writer.Close()


def _copclib_extra_bytes(header: laspy.LasHeader):
    """copclib's extra-bytes record for ``header``'s extra dimensions (names, types, descriptions, ranges).

    copclib's Python binding cannot build the descriptors itself (its ``EbVlr(n)`` makes n unnamed bytes), but
    its LAZ reader parses them: a one-point LAZ of ``header``, written by laspy, is read back for them."""
    import copclib

    with tempfile.TemporaryDirectory(prefix="muls-copc-") as folder:
        probe = Path(folder) / "header.laz"
        las = laspy.LasData(header)
        las.points = laspy.ScaleAwarePointRecord.zeros(1, header=header)
        las.write(probe)
        return copclib.LazReader(str(probe)).laz_config.extra_bytes_vlr


def write_copc(path, records: PointRecords, **kwargs) -> None:
    """Write all ``records`` to ``path`` (``*.copc.laz``) in one go; keyword arguments as :class:`CopcWriter`."""
    with CopcWriter(path, **kwargs) as copc:
        copc.write(records)
