"""Output files: LAS 1.4 round trips and header compliance (R15), atomicity, PLY, npz, JSON, CSV."""

from __future__ import annotations

import json
import os
import struct

import laspy
import numpy as np
import pytest
import trimesh

from scanner_sim import io
from scanner_sim.records import DROPOUT_CAUSES, DropoutRecords, PointRecords

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
        pulse_index=pulse,
    )


def make_dropouts(n: int = 300, seed: int = 1, first_pulse: int = 0) -> DropoutRecords:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return DropoutRecords(
        pulse_index=first_pulse + np.arange(n),
        time_s=(first_pulse + np.arange(n)) * 2e-4,
        origin=rng.uniform(-100, 100, (n, 3)),
        direction=d / np.linalg.norm(d, axis=1, keepdims=True),
        cause=rng.integers(0, len(DROPOUT_CAUSES), n),
    )


# ------------------------------------------------------------------------------------------
# records
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


def test_records_concatenate_empty_and_len():
    a, b = make_points(5), make_points(7, seed=3)
    c = PointRecords.concatenate([a, b])
    assert len(c) == 12 and c.xyz.shape == (12, 3)
    np.testing.assert_array_equal(c.snr[5:], b.snr)
    e = PointRecords.empty()
    assert len(e) == 0 and e.xyz.shape == (0, 3) and e.object_id.dtype == np.int32
    assert len(PointRecords.concatenate([])) == 0
    assert len(DropoutRecords.empty()) == 0
    d = DropoutRecords.concatenate([make_dropouts(3), make_dropouts(4)])
    assert len(d) == 7 and sum(d.counts_by_cause().values()) == 7
    with pytest.raises(ValueError, match="code 6 is unknown"):
        DropoutRecords(**{**make_dropouts(2).as_dict(), "cause": np.array([0, 6])})


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
                 "incidence_deg", "object_id"):
        np.testing.assert_array_equal(getattr(back, name), getattr(recs, name), err_msg=name)
    assert io.read_las_metadata(path)["pass_metadata"] == {"seed": 7}


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


# ------------------------------------------------------------------------------------------
# atomicity
# ------------------------------------------------------------------------------------------


class Boom(Exception):
    pass


def test_las_exception_leaves_no_file(tmp_path):
    with pytest.raises(Boom):
        with io.LasWriter(tmp_path / "points.las", offset_m=OFFSET) as las:
            las.write(make_points(100))
            assert len(os.listdir(tmp_path)) == 1  # the hidden temp file
            assert not (tmp_path / "points.las").exists()
            raise Boom
    assert os.listdir(tmp_path) == []


def test_las_old_file_untouched_until_new_one_is_complete(tmp_path):
    path = tmp_path / "points.las"
    io.write_las(path, make_points(50), offset_m=OFFSET)
    old = path.read_bytes()
    with pytest.raises(Boom):
        with io.LasWriter(path, offset_m=OFFSET) as las:
            las.write(make_points(80, seed=5))
            raise Boom
    assert path.read_bytes() == old and os.listdir(tmp_path) == ["points.las"]
    with io.LasWriter(path, offset_m=OFFSET) as las:
        las.write(make_points(80, seed=5))
        assert path.read_bytes() == old  # still the old file while writing
    assert laspy.read(path).header.point_count == 80
    assert os.listdir(tmp_path) == ["points.las"]


def test_atomic_path_interrupt_removes_temp_and_keeps_old(tmp_path):
    final = tmp_path / "summary.json"
    final.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with io.atomic_path(final) as tmp:
            tmp.write_text("half")
            assert tmp.name.startswith(".summary.json.") and tmp.name.endswith(".tmp")
            raise KeyboardInterrupt
    assert final.read_text() == "old" and os.listdir(tmp_path) == ["summary.json"]
    with pytest.raises(ValueError, match="does not exist"):
        with io.atomic_path(tmp_path / "missing" / "x.json"):
            pass


def test_other_writers_are_atomic_on_error(tmp_path):
    with pytest.raises(ValueError, match="not JSON-serialisable"):
        io.write_summary_json(tmp_path / "summary.json", {"x": object()})
    with pytest.raises(ValueError, match="channels"):
        io.write_waveforms_npz(tmp_path / "w.npz", [1], np.arange(4.0), {"time_ns": np.zeros((1, 4))})
    with pytest.raises(Boom):
        with io.DropoutWriter(tmp_path / "dropouts.npz") as w:
            w.write(make_dropouts(10))
            raise Boom
    assert os.listdir(tmp_path) == []


# ------------------------------------------------------------------------------------------
# dropouts, summary, trajectory, PLY, waveforms
# ------------------------------------------------------------------------------------------


def test_dropouts_npz_round_trip_and_streaming(tmp_path):
    chunks = [make_dropouts(200, seed=s, first_pulse=500 * s) for s in range(3)]
    whole = DropoutRecords.concatenate(chunks)
    io.write_dropouts_npz(tmp_path / "once.npz", whole)
    with io.DropoutWriter(tmp_path / "stream.npz") as w:
        for c in chunks:
            w.write(c)
    assert w.counts_by_cause() == whole.counts_by_cause()
    assert sorted(os.listdir(tmp_path)) == ["once.npz", "stream.npz"]  # spool removed
    for name in ("once.npz", "stream.npz"):
        back = io.read_dropouts_npz(tmp_path / name)
        for field in DropoutRecords.field_names():
            np.testing.assert_array_equal(getattr(back, field), getattr(whole, field), err_msg=field)
    with np.load(tmp_path / "stream.npz") as z:
        assert tuple(z["cause_names"]) == DROPOUT_CAUSES
    with io.DropoutWriter(tmp_path / "none.npz"):
        pass
    assert len(io.read_dropouts_npz(tmp_path / "none.npz")) == 0


def test_summary_json_converts_numpy(tmp_path):
    summary = {"scene": "cable_survey", "seed": np.int64(3), "pulses_per_s": np.float32(5.5e4),
               "dropouts": {"no_hit": np.uint32(2)}, "range_error_m": {"median": np.nan},
               "bbox": np.array([1.0, 2.0]), "flag": np.bool_(True)}
    io.write_summary_json(tmp_path / "summary.json", summary)
    text = (tmp_path / "summary.json").read_text()
    back = json.loads(text)
    assert list(back) == list(summary)  # insertion order, not sorted
    assert back["seed"] == 3 and back["dropouts"]["no_hit"] == 2 and back["flag"] is True
    assert back["range_error_m"]["median"] is None and back["bbox"] == [1.0, 2.0]
    assert '\n  "scene"' in text


def test_trajectory_csv_round_trip(tmp_path):
    n = 50
    t = np.linspace(0, 10, n)
    pos = np.column_stack([t * 1.5 + 500000.0, np.zeros(n), np.full(n, -20.0)])
    rpy = np.column_stack([np.zeros(n), np.ones(n), np.full(n, 90.0)])
    io.write_trajectory_csv(tmp_path / "trajectory.csv", t, pos, rpy,
                            estimated_position_m=pos + 0.01, estimated_attitude=rpy + 0.1)
    first = (tmp_path / "trajectory.csv").read_text().splitlines()[0]
    assert first.startswith("time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg,est_x_m")
    back = io.read_trajectory_csv(tmp_path / "trajectory.csv")
    np.testing.assert_allclose(back["x_m"], pos[:, 0], atol=1e-6)
    np.testing.assert_allclose(back["est_yaw_deg"], 90.1)
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    io.write_trajectory_csv(tmp_path / "q.csv", t, pos, q, attitude_format="quaternion")
    assert set(io.read_trajectory_csv(tmp_path / "q.csv")) >= {"qw", "qx", "qy", "qz"}
    with pytest.raises(ValueError, match="attitude: shape"):
        io.write_trajectory_csv(tmp_path / "bad.csv", t, pos, q)


def test_scene_ply_round_trip_with_trimesh(tmp_path):
    box = trimesh.creation.box(extents=(2.0, 3.0, 1.0))
    vertices = box.vertices + np.asarray(OFFSET)
    labels = np.arange(len(box.faces)) % 4 + 2
    oids = np.arange(len(box.faces)) * 10 - 1
    path = tmp_path / "scene.ply"
    io.write_scene_ply(path, vertices, box.faces, labels, oids)
    mesh = trimesh.load(path, process=False)
    np.testing.assert_array_equal(mesh.vertices, vertices)  # doubles: no float32 rounding
    np.testing.assert_array_equal(mesh.faces, box.faces)
    face_data = mesh.metadata["_ply_raw"]["face"]["data"]
    np.testing.assert_array_equal(face_data["label"], labels)
    np.testing.assert_array_equal(face_data["object_id"], oids)
    back = io.read_scene_ply(path)
    np.testing.assert_array_equal(back["face_label"], labels)
    np.testing.assert_array_equal(back["face_object_id"], oids)
    with pytest.raises(ValueError, match="face_label: values span"):
        io.write_scene_ply(tmp_path / "x.ply", vertices, box.faces, labels + 300, oids)


def test_waveforms_npz_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    ch = {f"ch{i}": rng.integers(0, 1024, (3, 400)).astype(np.uint16) for i in range(4)}
    io.write_waveforms_npz(tmp_path / "waveforms.npz", [5, 9, 12], np.arange(400.0), ch)
    pi, t, back = io.read_waveforms_npz(tmp_path / "waveforms.npz")
    np.testing.assert_array_equal(pi, [5, 9, 12])
    assert t.shape == (400,) and list(back) == list(ch)
    for k in ch:
        np.testing.assert_array_equal(back[k], ch[k])
        assert back[k].dtype == np.uint16
    with pytest.raises(ValueError, match=r"channels\['ch1'\]: shape"):
        io.write_waveforms_npz(tmp_path / "w.npz", [1], np.arange(4.0), {"ch1": np.zeros((2, 4))})
