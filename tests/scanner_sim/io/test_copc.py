"""points.copc.laz: the LAS points and extra bytes in a COPC octree that laspy's CopcReader queries by bounds."""

from __future__ import annotations

import laspy
import numpy as np
import pyproj
import pytest
from laspy.copc import Bounds, CopcReader, load_octree_for_query

from scanner_sim import cli, io
from scanner_sim.io.copc import GRID_CELLS, CopcWriter, octree_levels, write_copc
from scanner_sim.records.point_records import PointRecords

#: Dimensions compared point for point between the LAS and the COPC (standard ones, then every extra one).
STANDARD = ("X", "Y", "Z", "intensity", "return_number", "number_of_returns", "classification", "scan_angle",
            "gps_time", "point_source_id", "scanner_channel", "synthetic")


@pytest.fixture(scope="module")
def copc_pass(tmp_path_factory):
    """A 5,000-pulse cable_survey pass written with --copc, beside its points.las."""
    out = tmp_path_factory.mktemp("copc") / "pass"
    assert cli.main(["run", "cable_survey", "--max-pulses", "5000", "--copc", "--no-render", "--quiet",
                     "--out", str(out)]) == 0
    return out


def _rows(points, dims) -> np.ndarray:
    """The points as rows of ``dims``, sorted, so that two files' point sets compare whatever their order."""
    table = np.rec.fromarrays([np.asarray(points[d]) for d in dims], names=list(dims))
    return np.sort(table, order=list(dims))


def test_run_copc_holds_the_las_points_extra_bytes_and_crs(copc_pass):
    las = laspy.read(copc_pass / "points.las")
    with CopcReader.open(copc_pass / "points.copc.laz") as reader:
        copc = reader.query()
        extra = list(reader.header.point_format.extra_dimension_names)
        assert reader.header.point_count == len(las.points) > 1000
        assert reader.header.offsets.tolist() == las.header.offsets.tolist()
    assert extra == list(las.point_format.extra_dimension_names) == list(io.EXTRA_DIMENSIONS)
    assert {"thu_m", "tvu_m"} <= set(extra)
    for name in extra:
        assert copc.point_format.dimension_by_name(name).dtype == las.point_format.dimension_by_name(name).dtype
    dims = STANDARD + tuple(extra)
    got, want = _rows(copc, dims), _rows(las.points, dims)
    assert got.dtype == want.dtype and got.tobytes() == want.tobytes()  # bit for bit, NaN included
    assert np.isfinite(np.asarray(copc["tvu_m"])).all()  # the uncertainty travelled, not NaN placeholders
    with laspy.open(copc_pass / "points.copc.laz") as f:  # the CRS travels as an extended record
        wkt = [v.string for v in f.header.evlrs if isinstance(v, laspy.vlrs.known.WktCoordinateSystemVlr)]
    assert wkt == [las.header.vlrs.get("WktCoordinateSystemVlr")[0].string]


def test_bounds_query_returns_exactly_the_las_points_inside(copc_pass, tmp_path):
    """An octree several levels deep (leaves of at most 300 points): each query box returns the LAS points inside it,
    no more, no fewer, and reads fewer nodes than the whole tree. Inside means at the file's resolution: laspy
    compares the stored millimetre counts, so the boxes' edges are put on that grid."""
    records = io.read_las(copc_pass / "points.las")
    las = laspy.read(copc_pass / "points.las")
    path = tmp_path / "deep.copc.laz"
    write_copc(path, records, offset_m=las.header.offsets, max_node_points=300)
    rng = np.random.default_rng(3)
    lo, hi = las.xyz.min(axis=0), las.xyz.max(axis=0)
    offset, scale = las.header.offsets, las.header.scales
    counts = np.column_stack([las.X, las.Y, las.Z])
    with CopcReader.open(path) as reader:
        every = load_octree_for_query(reader.source, reader.copc_info, reader.root_page, query_bounds=None)
        assert max(node.key.level for node in every) >= 2
        for _ in range(5):
            centre, half = las.xyz[rng.integers(len(las.xyz))], rng.uniform(0.3, 3.0, 3)
            a, b = centre - half, centre + half
            if rng.random() < 0.5:  # a plan box, as a GIS asks
                a[2], b[2] = lo[2] - 1.0, hi[2] + 1.0
            # box edges on the file's millimetre grid: laspy compares the stored integer counts
            a, b = (np.round((e - offset) / scale) * scale + offset for e in (a, b))
            got = reader.query(Bounds(mins=a, maxs=b))
            lo_counts, hi_counts = (np.round((e - offset) / scale) for e in (a, b))
            inside = np.all((counts >= lo_counts) & (counts <= hi_counts), axis=1)
            assert 0 < len(got) == inside.sum()
            dims = ("X", "Y", "Z", "gps_time", "thu_m", "tvu_m")
            assert _rows(got, dims).tobytes() == _rows(las.points[inside], dims).tobytes()
            nodes = load_octree_for_query(reader.source, reader.copc_info, reader.root_page,
                                          query_bounds=Bounds(mins=a, maxs=b).ensure_3d(reader.header.mins,
                                                                                        reader.header.maxs))
            assert len(nodes) < len(every)


def test_projected_crs_survives(tmp_path):
    from test_io_las import OFFSET, make_points

    utm = pyproj.CRS("EPSG:26918")
    path = tmp_path / "utm.copc.laz"
    write_copc(path, make_points(2000), offset_m=OFFSET, crs_wkt=utm.to_wkt("WKT1_GDAL"))
    with laspy.open(path) as f:
        assert f.header.parse_crs().to_epsg() == 26918


def test_every_point_lies_in_its_node_and_inner_nodes_keep_one_point_a_cell():
    rng = np.random.default_rng(0)
    xyz = np.r_[rng.normal(0.0, 3.0, (20_000, 3)), np.full((500, 3), 1.25)]  # a tight cluster of repeated points
    centre, half, keys = octree_levels(xyz, max_node_points=400)
    step = 2.0 * half / (1 << keys[:, 0])[:, None]
    corner = centre - half + keys[:, 1:] * step
    assert np.all((xyz >= corner) & (xyz < corner + step))
    counts = {}
    for key in map(tuple, keys):
        counts[key] = counts.get(key, 0) + 1
    for key, count in counts.items():
        children = [k for k in counts if k[0] == key[0] + 1 and all(k[i] // 2 == key[i] for i in (1, 2, 3))]
        if children:  # an inner node: at most one point per cell of its grid
            rows = np.flatnonzero(np.all(keys == key, axis=1))
            cell = np.floor((xyz[rows] - (centre - half)) / (step[rows] / GRID_CELLS)).astype(np.int64)
            assert len(np.unique(cell, axis=0)) == count
    assert keys[:, 0].max() >= 2


def test_an_interrupted_copc_leaves_nothing(tmp_path):
    from test_io_las import OFFSET, make_points

    path = tmp_path / "points.copc.laz"
    with pytest.raises(KeyboardInterrupt), CopcWriter(path, offset_m=OFFSET) as writer:
        writer.write(make_points(100))
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match=r"must end in \.copc\.laz"):
        CopcWriter(tmp_path / "points.laz")


def test_scene_key_output_copc_writes_the_file(tmp_path):
    out = tmp_path / "pass"
    assert cli.main(["run", "pool_panel", "--max-pulses", "200", "--set", "output.copc=true", "--no-render", "--quiet",
                     "--out", str(out)]) == 0
    with CopcReader.open(out / "points.copc.laz") as reader:
        assert reader.header.point_count == len(io.read_las(out / "points.las")) > 0


def test_records_round_trip_through_read_las(copc_pass):
    """laspy reads COPC as LAZ 1.4, so io.read_las gives back the pass's records from either file."""
    a, b = io.read_las(copc_pass / "points.las"), io.read_las(copc_pass / "points.copc.laz")
    order_a, order_b = np.lexsort(a.xyz.T[::-1]), np.lexsort(b.xyz.T[::-1])
    for name in ("xyz", "gps_time_s", "classification", "thu_m", "tvu_m", "range_error_m"):
        assert np.array_equal(getattr(a, name)[order_a], getattr(b, name)[order_b], equal_nan=True), name
    assert isinstance(b, PointRecords)


def test_a_pass_without_points_writes_an_empty_copc(tmp_path):
    path = tmp_path / "empty.copc.laz"
    write_copc(path, PointRecords.empty())
    with CopcReader.open(path) as reader:
        assert reader.header.point_count == 0 and len(reader.query()) == 0
