"""points.las: the point schema, LAS 1.4 round trips, header compliance (R15), streaming, atomicity, and the
laspy extra-bytes workaround."""

from __future__ import annotations

import os
import struct

import laspy
import numpy as np
import pytest

from scanner_sim import io
from scanner_sim.io.las import _set_extra_bytes_ranges
from scanner_sim.records.point_records import LasExtra, LasStandard, PointRecords

OFFSET = (500_000.0, 6_000_000.0, -40.0)  # a UTM-like local origin: large world coordinates

#: LAS quantisation allowed by the acceptance criteria [m].
MAX_QUANTISATION_M = 0.001


def make_points(n: int = 500, seed: int = 0, first_pulse: int = 0) -> PointRecords:
    rng = np.random.default_rng(seed)
    pulse = first_pulse + np.arange(n) // 2
    nret = np.where(pulse % 3 == 0, 2, 1)
    ret = np.where((nret == 2) & (np.arange(n) % 2 == 1), 2, 1)
    return PointRecords(
        gps_time_s=pulse * 2e-4,
        xyz=np.asarray(OFFSET) + rng.uniform(-60.0, 60.0, (n, 3)),
        intensity=rng.integers(0, 65536, n),
        return_number=ret,
        number_of_returns=nret,
        classification=rng.integers(0, 70, n),
        scan_angle_deg=rng.uniform(-179.0, 179.0, n),
        channel=rng.integers(1, 4, n),
        amplitude_lsb=rng.uniform(0, 1023, n),
        snr=rng.uniform(0, 200, n),
        saturated=rng.random(n) < 0.2,
        true_range_m=rng.uniform(1, 12, n),
        range_error_m=rng.normal(0, 0.02, n),
        incidence_deg=rng.uniform(0, 89, n),
        object_id=rng.integers(-1, 20, n),
        leg=rng.integers(1, 9, n),
        pulse_index=pulse,
        thu_m=rng.uniform(0.01, 0.3, n),
        tvu_m=rng.uniform(0.01, 0.3, n),
        tvu_surface_m=rng.uniform(0.01, 0.4, n),
    )


class Boom(Exception):
    pass


# ------------------------------------------------------------------------------------------
# the point schema
# ------------------------------------------------------------------------------------------


def test_records_validation_names_the_field():
    good = make_points(4).as_dict()
    with pytest.raises(ValueError, match="PointRecords.snr: length 3"):
        PointRecords(**{**good, "snr": good["snr"][:3]})
    with pytest.raises(ValueError, match=r"PointRecords.xyz: shape \(4,\)"):
        PointRecords(**{**good, "xyz": np.zeros(4)})
    with pytest.raises(ValueError, match="PointRecords.classification: values span"):
        PointRecords(**{**good, "classification": np.array([0, 1, 2, 300])})
    with pytest.raises(ValueError, match="PointRecords.channel: dtype float64"):
        PointRecords(**{**good, "channel": np.array([1.0, 2.0, 3.0, 1.0])})


def test_point_records_concatenate_empty_and_len():
    a, b = make_points(5), make_points(7, seed=3)
    c = PointRecords.concatenate([a, b])
    assert len(c) == 12 and c.xyz.shape == (12, 3)
    np.testing.assert_array_equal(c.snr[5:], b.snr)
    e = PointRecords.empty()
    assert len(e) == 0 and e.xyz.shape == (0, 3) and e.object_id.dtype == np.int32
    assert len(PointRecords.concatenate([])) == 0
    np.testing.assert_array_equal(c.select(c.saturated).snr, c.snr[c.saturated])


def test_las_layout_is_derived_from_the_point_declarations():
    """Every PointRecords field is a standard dimension, an extra dimension (in declaration order), or
    declared as not stored; the point record is 30 standard bytes plus the extra dimensions."""
    columns = PointRecords.columns()
    assert tuple(columns) == PointRecords.field_names()
    extras = [name for name, col in columns.items() if isinstance(col.las, LasExtra)]
    assert list(io.EXTRA_DIMENSIONS) == extras
    assert all(len(desc) <= 32 for _, desc in io.EXTRA_DIMENSIONS.values())
    standard = {name for name, col in columns.items() if isinstance(col.las, LasStandard)}
    assert standard == {"gps_time_s", "xyz", "intensity", "return_number", "number_of_returns",
                        "classification", "scan_angle_deg", "leg"}
    assert [name for name, col in columns.items() if col.las is None] == ["pulse_index"]
    header = laspy.LasHeader(version="1.4", point_format=6)
    dims = {d for col in columns.values() if isinstance(col.las, LasStandard) for d in col.las.dimensions}
    assert dims <= set(header.point_format.dimension_names)
    assert 30 + sum(dtype.itemsize for dtype, _ in io.EXTRA_DIMENSIONS.values()) == 68  # thu_m, tvu_m, tvu_surface_m: 12 bytes


# ------------------------------------------------------------------------------------------
# LAS
# ------------------------------------------------------------------------------------------


def test_las_round_trip_preserves_every_field(tmp_path):
    recs = make_points()
    path = tmp_path / "points.las"
    io.write_las(path, recs, offset_m=OFFSET, gps_time_offset_s=3.5e8, metadata={"seed": 7})
    back = io.read_las(path)
    assert len(back) == len(recs)
    assert np.abs(back.xyz - recs.xyz).max() <= MAX_QUANTISATION_M / 2 + 1e-9
    np.testing.assert_allclose(back.gps_time_s, recs.gps_time_s, atol=1e-6)  # offset 3.5e8 s: ulp 6e-8 s
    assert np.abs(back.scan_angle_deg - recs.scan_angle_deg).max() <= io.SCAN_ANGLE_UNIT_DEG / 2 + 1e-5
    for name in ("intensity", "return_number", "number_of_returns", "classification", "channel",
                 "amplitude_lsb", "snr", "saturated", "true_range_m", "range_error_m",
                 "incidence_deg", "object_id", "leg"):
        np.testing.assert_array_equal(getattr(back, name), getattr(recs, name), err_msg=name)
    assert io.read_las_metadata(path)["pass_metadata"] == {"seed": 7}


def test_las_carries_the_lidar_conventions(tmp_path):
    """point_source_id is the point's leg, scanner_channel its detection channel (2 bits: channels above 3
    read 0 there and stay whole in the `channel` extra dimension), every point is flagged synthetic, and the
    CRS is a WKT VLR with the global-encoding WKT bit set (what PDAL-style readers look for)."""
    recs = make_points()
    recs = PointRecords(**{**recs.as_dict(), "channel": np.where(np.arange(len(recs)) == 0, 5, recs.channel)})
    path = tmp_path / "points.las"
    io.write_las(path, recs, offset_m=OFFSET)
    las = laspy.read(path)
    np.testing.assert_array_equal(las.point_source_id, recs.leg)
    np.testing.assert_array_equal(las.scanner_channel[1:], recs.channel[1:])
    assert las.scanner_channel[0] == 0 and las.channel[0] == 5
    assert np.all(las.synthetic == 1)
    assert las.header.global_encoding.wkt
    wkt = [v for v in las.header.vlrs if v.record_id == 2112]
    assert len(wkt) == 1 and wkt[0].user_id == "LASF_Projection"


def test_las_extra_dimensions_have_declared_types(tmp_path):
    path = tmp_path / "points.las"
    io.write_las(path, make_points(10), offset_m=OFFSET)
    las = laspy.read(path)
    assert str(las.header.version) == "1.4" and las.header.point_format.id == 6
    assert las.header.point_count == 10
    extra = {d.name: d.dtype for d in las.point_format.extra_dimensions}
    assert extra == {name: dtype for name, (dtype, _) in io.EXTRA_DIMENSIONS.items()}
    ebv = las.header.vlrs.get("ExtraBytesVlr")
    assert len(ebv) == 1 and len(ebv[0].extra_bytes_structs) == len(io.EXTRA_DIMENSIONS)
    assert np.all(las.header.scales <= MAX_QUANTISATION_M)
    np.testing.assert_array_equal(las.header.offsets, OFFSET)


def test_las_scan_angle_units_and_wrapping():
    raw = io.scan_angle_to_las(np.array([0.0, 0.006, -30.0, 180.0, 350.0]))
    np.testing.assert_array_equal(raw, [0, 1, -5000, -30000, -1667])


def test_las_rejects_values_format_6_cannot_hold(tmp_path):
    bad = make_points(4).as_dict()
    bad["return_number"] = np.array([1, 1, 16, 1])
    bad["number_of_returns"] = np.array([1, 1, 16, 1])
    with pytest.raises(ValueError, match="return_number"):
        io.write_las(tmp_path / "a.las", PointRecords(**bad), offset_m=OFFSET)
    with pytest.raises(ValueError, match="offset_m"):
        io.write_las(tmp_path / "b.las", make_points(4), offset_m=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="suffix"):
        io.LasWriter(tmp_path / "c.xyz")
    assert os.listdir(tmp_path) == []


def test_las_streaming_chunks_equal_one_shot(tmp_path):
    chunks = [make_points(300, seed=s, first_pulse=1000 * s) for s in range(4)]
    chunks.insert(2, PointRecords.empty())
    with io.LasWriter(tmp_path / "stream.las", offset_m=OFFSET) as las:
        for c in chunks:
            las.write(c)
    assert las.point_count == 1200
    io.write_las(tmp_path / "once.las", PointRecords.concatenate(chunks), offset_m=OFFSET)
    a = (tmp_path / "stream.las").read_bytes()
    b = (tmp_path / "once.las").read_bytes()
    assert len(a) == len(b)
    assert a[:90] == b[:90] and a[94:] == b[94:]  # bytes 90..93: creation day and year


def test_las_empty_pass_is_a_valid_file(tmp_path):
    with io.LasWriter(tmp_path / "points.las", offset_m=OFFSET):
        pass
    las = laspy.read(tmp_path / "points.las")
    assert las.header.point_count == 0 and len(io.read_las(tmp_path / "points.las")) == 0


def _parse_las14_header(data: bytes) -> dict:
    """The LAS 1.4 public header block, field by field (LAS 1.4 R15, Table 3)."""
    h = {}
    h["signature"] = data[0:4]
    h["file_source_id"], h["global_encoding"] = struct.unpack_from("<HH", data, 4)
    h["version"] = struct.unpack_from("<BB", data, 24)
    h["system_identifier"] = data[26:58]
    h["generating_software"] = data[58:90]
    (h["header_size"], h["offset_to_point_data"], h["n_vlrs"], h["point_format"],
     h["point_record_length"], h["legacy_point_count"]) = struct.unpack_from("<HIIBHI", data, 94)
    h["legacy_points_by_return"] = struct.unpack_from("<5I", data, 111)
    h["scale"] = struct.unpack_from("<3d", data, 131)
    h["offset"] = struct.unpack_from("<3d", data, 155)
    maxx, minx, maxy, miny, maxz, minz = struct.unpack_from("<6d", data, 179)
    h["max"], h["min"] = (maxx, maxy, maxz), (minx, miny, minz)
    (h["start_of_waveform"], h["start_of_first_evlr"], h["n_evlrs"],
     h["point_count"]) = struct.unpack_from("<QQIQ", data, 227)
    h["points_by_return"] = struct.unpack_from("<15Q", data, 255)
    return h


def test_las_header_follows_las14_r15(tmp_path):
    """Check the bytes against the LAS 1.4 R15 specification (no LAStools/PDAL on this machine)."""
    recs = make_points(401)
    path = tmp_path / "points.las"
    io.write_las(path, recs, offset_m=OFFSET, file_source_id=12)
    data = path.read_bytes()
    h = _parse_las14_header(data)

    assert h["signature"] == b"LASF"
    assert h["version"] == (1, 4)
    assert h["header_size"] == 375
    assert h["file_source_id"] == 12
    ge = h["global_encoding"]
    assert ge & 0x01, "GPS time type bit: Adjusted Standard GPS time"
    assert ge & 0x10, "WKT bit: required for point data record formats 6-10"
    assert ge & 0b110 == 0, "no waveform data packets"
    assert ge & 0x08 == 0, "return numbers are not synthetic"
    assert ge & 0xFFE0 == 0, "reserved bits are zero"
    assert h["system_identifier"].rstrip(b"\0") and h["generating_software"].rstrip(b"\0")
    assert h["point_format"] == 6  # bit 7 (compression) clear: uncompressed LAS
    extra_bytes = sum(dtype.itemsize for dtype, _ in io.EXTRA_DIMENSIONS.values())
    assert h["point_record_length"] == 30 + extra_bytes
    # Formats 6-10 are not legacy compatible: legacy counts must be zero (R15, 2.4).
    assert h["legacy_point_count"] == 0 and h["legacy_points_by_return"] == (0,) * 5
    assert h["point_count"] == len(recs)
    by_return = np.bincount(recs.return_number, minlength=16)[1:16]
    assert h["points_by_return"] == tuple(int(c) for c in by_return)
    assert h["start_of_waveform"] == 0 and h["n_evlrs"] == 0 and h["start_of_first_evlr"] == 0
    assert all(s <= MAX_QUANTISATION_M for s in h["scale"])
    np.testing.assert_array_equal(h["offset"], OFFSET)
    np.testing.assert_allclose(h["max"], recs.xyz.max(axis=0), atol=MAX_QUANTISATION_M)
    np.testing.assert_allclose(h["min"], recs.xyz.min(axis=0), atol=MAX_QUANTISATION_M)

    # VLRs: 54-byte headers, reserved 0, exactly one extra-bytes and one WKT record, no GeoTIFF keys.
    pos, vlrs = 375, []
    for _ in range(h["n_vlrs"]):
        reserved, user_id, record_id, length = struct.unpack_from("<H16sHH", data, pos)
        assert reserved == 0
        vlrs.append((user_id.rstrip(b"\0").decode(), record_id, data[pos + 54: pos + 54 + length]))
        pos += 54 + length
    assert pos == h["offset_to_point_data"]
    assert len(data) == h["offset_to_point_data"] + len(recs) * h["point_record_length"]
    keys = [(u, r) for u, r, _ in vlrs]
    assert keys.count(("LASF_Spec", 4)) == 1
    assert keys.count(("LASF_Projection", 2112)) == 1
    assert ("LASF_Projection", 34735) not in keys
    wkt = next(p for u, r, p in vlrs if (u, r) == ("LASF_Projection", 2112))
    assert wkt.endswith(b"\0") and wkt.rstrip(b"\0").decode() == io.LOCAL_ENGINEERING_WKT

    # Extra bytes descriptors (R15 Table 24): 192 bytes each, in point-record order.
    payload = next(p for u, r, p in vlrs if (u, r) == ("LASF_Spec", 4))
    assert len(payload) == 192 * len(io.EXTRA_DIMENSIONS)
    type_codes = {np.dtype(np.uint8): 1, np.dtype(np.int32): 6, np.dtype(np.float32): 9}
    long_types = {"u": "<u8", "i": "<i8", "f": "<f8"}
    for i, (name, (dtype, desc)) in enumerate(io.EXTRA_DIMENSIONS.items()):
        rec = payload[192 * i: 192 * (i + 1)]
        assert rec[0:2] == b"\0\0"
        assert rec[2] == type_codes[dtype], name
        assert rec[3] & 0b11001 == 0, "no no_data, scale or offset"
        assert rec[3] & 0b00110 == 0b00110, "min and max given"
        assert rec[4:36].rstrip(b"\0").decode() == name
        assert rec[36:40] == b"\0" * 4
        values = getattr(recs, name).astype(dtype)
        lt = long_types[dtype.kind]
        assert np.frombuffer(rec[64:72], lt)[0] == values.min(), f"{name} min"  # R15: no_data 40, min 64
        assert np.frombuffer(rec[88:96], lt)[0] == values.max(), f"{name} max"  # max 88
        assert rec[160:192].rstrip(b"\0").decode() == desc


def test_las_extra_bytes_ranges_cover_all_chunks(tmp_path):
    """Regression: laspy 2.7 fills extra-bytes min/max from the first point of each chunk.

    Root cause: ``ExtraBytesStruct.grow`` indexes ``points[name][..., 0]`` on a 1-D field, which
    picks one point, not the minimum. LasWriter writes the true ranges itself.
    """
    chunks = [make_points(100, seed=s) for s in range(3)]
    with io.LasWriter(tmp_path / "p.las", offset_m=OFFSET) as las:
        for c in chunks:
            las.write(c)
    structs = laspy.read(tmp_path / "p.las").header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs
    whole = PointRecords.concatenate(chunks)
    for s in structs:
        name = bytes(s.name).rstrip(b"\0").decode()
        values = getattr(whole, name).astype(io.EXTRA_DIMENSIONS[name][0])
        assert s.min[0] == values.min() and s.max[0] == values.max(), name


def test_regression_extra_bytes_ranges_skip_the_nan_of_points_without_a_surface(tmp_path):
    """Regression: a campaign's pass and the same serial pass wrote different LAS headers.

    Root cause: a point ranged on the water column has no surface, so its ``incidence_deg`` is nan; the writer
    took each chunk's ``min()``/``max()`` (nan when the chunk holds one) and merged them with Python's ``min``,
    whose answer with a nan depends on the order of its arguments. The range is now that of the known values,
    in whatever order the chunks come.
    """
    chunks = [make_points(50, seed=s) for s in range(3)]
    chunks[1].incidence_deg[:5] = np.nan
    whole = PointRecords.concatenate(chunks)
    expected = (np.nanmin(whole.incidence_deg), np.nanmax(whole.incidence_deg))
    for order in ([0, 1, 2], [1, 0, 2], [2, 1, 0]):
        with io.LasWriter(tmp_path / "p.las", offset_m=OFFSET) as las:
            for i in order:
                las.write(chunks[i])
        structs = laspy.read(tmp_path / "p.las").header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs
        (s,) = [s for s in structs if bytes(s.name).rstrip(b"\0").decode() == "incidence_deg"]
        assert (s.min[0], s.max[0]) == pytest.approx(expected, rel=1e-6), order


def test_laspy_extra_bytes_range_bug_still_present(tmp_path):
    """Pins the laspy bug that ``_set_extra_bytes_ranges`` works around: this fails once laspy is fixed.

    Root cause: laspy 2.7 ``ExtraBytesStruct.grow`` takes ``points[name][..., 0]`` of a 1-D field, which
    is the chunk's first point, not the chunk, so the extra bytes descriptor's min and max written
    through laspy's public API are those of the first point. laspy offers no public setter for them.
    When this test fails, laspy tracks the true range itself: delete ``_set_extra_bytes_ranges`` (and
    this test) and check that the LAS bytes stay the same.
    """
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.add_extra_dims([laspy.ExtraBytesParams(name="snr", type=np.float32)])
    pts = laspy.ScaleAwarePointRecord.zeros(3, header=header)
    pts["snr"] = np.array([5.0, 1.0, 9.0], dtype=np.float32)
    with laspy.open(tmp_path / "plain.las", mode="w", header=header) as writer:
        writer.write_points(pts)
    (struct_,) = laspy.read(tmp_path / "plain.las").header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs
    assert (struct_.min[0], struct_.max[0]) == (5.0, 5.0), "laspy now tracks extra-bytes ranges itself"

    with laspy.open(tmp_path / "fixed.las", mode="w", header=header) as writer:
        writer.write_points(pts)
        _set_extra_bytes_ranges(writer.header, {"snr": (1.0, 9.0)})
    (struct_,) = laspy.read(tmp_path / "fixed.las").header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs
    assert (struct_.min[0], struct_.max[0]) == (1.0, 9.0)


def test_read_las_of_another_tool_fills_unknown_fields(tmp_path):
    """A format 1 LAS without extra dimensions: whole-degree scan angle, declared unknown values."""
    las = laspy.LasData(laspy.LasHeader(version="1.2", point_format=1))
    las.x, las.y, las.z = np.array([1.0, 2.0]), np.array([3.0, 4.0]), np.array([5.0, 6.0])
    las.scan_angle_rank = np.array([-12, 30])
    las.gps_time = np.array([10.0, 11.0])
    las.return_number = las.number_of_returns = np.array([1, 1])
    las.write(tmp_path / "other.las")
    back = io.read_las(tmp_path / "other.las")
    np.testing.assert_array_equal(back.scan_angle_deg, [-12.0, 30.0])
    np.testing.assert_array_equal(back.gps_time_s, [10.0, 11.0])
    np.testing.assert_array_equal(back.object_id, [-1, -1])
    np.testing.assert_array_equal(back.pulse_index, [-1, -1])
    np.testing.assert_array_equal(back.channel, [0, 0])
    np.testing.assert_allclose(back.xyz, [[1, 3, 5], [2, 4, 6]], atol=0.01)


# ------------------------------------------------------------------------------------------
# atomicity
# ------------------------------------------------------------------------------------------


def test_las_exception_leaves_no_file(tmp_path):
    with pytest.raises(Boom), io.LasWriter(tmp_path / "points.las", offset_m=OFFSET) as las:
        las.write(make_points(100))
        assert len(os.listdir(tmp_path)) == 1  # the hidden temp file
        assert not (tmp_path / "points.las").exists()
        raise Boom
    assert os.listdir(tmp_path) == []


def test_las_old_file_untouched_until_new_one_is_complete(tmp_path):
    path = tmp_path / "points.las"
    io.write_las(path, make_points(50), offset_m=OFFSET)
    old = path.read_bytes()
    with pytest.raises(Boom), io.LasWriter(path, offset_m=OFFSET) as las:
        las.write(make_points(80, seed=5))
        raise Boom
    assert path.read_bytes() == old and os.listdir(tmp_path) == ["points.las"]
    with io.LasWriter(path, offset_m=OFFSET) as las:
        las.write(make_points(80, seed=5))
        assert path.read_bytes() == old  # still the old file while writing
    assert laspy.read(path).header.point_count == 80
    assert os.listdir(tmp_path) == ["points.las"]
