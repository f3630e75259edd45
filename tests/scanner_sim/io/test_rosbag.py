"""ROS 2 bags of a pass (scanner_sim/io/rosbag.py), read back with rosbags' own reader: the PointCloud2 messages
hold the LAS's points, the stamps follow the LAS's time, odometry and tf cover the pass, NED turns the axes as
docs/outputs.md says, and the bag is written atomically under its folder's lock."""

import csv
from datetime import datetime, timezone

import laspy
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from scanner_sim.cli import main
from scanner_sim.config import load_scene
from scanner_sim.io import rosbag
from scanner_sim.io.run_dir import OutputBusyError, OutputLock
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions, PassPlan

PULSES = 3000
#: cable_survey's scanner: oscillating at 8 Hz, one line per half period.
LINES_PER_S = 16.0
#: PointField datatype -> numpy type (sensor_msgs/msg/PointField constants).
NUMPY_OF = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)  # the reader's own, not the writer's


def _pass(tmp_path, name="run", pulses=PULSES, **settings):
    """A short cable_survey pass with a bag in ``name``/rosbag; returns the run folder."""
    keys = {f"output.rosbag.{k}": v for k, v in settings.items()} or {"output.rosbag": {}}
    config = load_scene("cable_survey").with_overrides(keys)
    out = tmp_path / name
    run_pass(config, out, PassOptions(max_pulses=pulses, progress=False, render=False, write_scene=False))
    return out


def _read_bag(path):
    """topic -> list of (log time [ns], message), read with rosbags' Reader and deserialize_cdr."""
    topics = {}
    with Reader(path) as reader:
        for connection, stamp, raw in reader.messages():
            topics.setdefault(connection.topic, []).append((stamp, TYPESTORE.deserialize_cdr(raw, connection.msgtype)))
    return topics


def _points(message):
    """A PointCloud2's points as a numpy structured array, laid out by its own fields."""
    dtype = np.dtype({"names": [f.name for f in message.fields], "offsets": [f.offset for f in message.fields],
                      "formats": ["<" + NUMPY_OF[f.datatype] for f in message.fields], "itemsize": message.point_step})
    assert message.height == 1 and message.row_step == message.point_step * message.width
    return np.frombuffer(message.data.tobytes(), dtype)


def _stamp(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


@pytest.fixture(scope="module")
def enu_pass(tmp_path_factory):
    out = _pass(tmp_path_factory.mktemp("enu"))
    return out, _read_bag(out / "rosbag"), laspy.read(out / "points.las")


def test_bag_points_are_the_las_points(enu_pass):
    """Same count, same order, coordinates on the LAS's millimetre grid (the LAS offset is the local origin), same
    classes, objects, channels, intensities and truth errors."""
    out, topics, las = enu_pass
    messages = [m for _, m in topics["/points"]]
    assert all(m.is_dense and m.header.frame_id == "world" for m in messages)
    points = np.concatenate([_points(m) for m in messages])
    assert len(points) == las.header.point_count > 1000
    for axis, counts in zip("xyz", (las.X, las.Y, las.Z)):  # the LAS's int32 counts of 1 mm
        np.testing.assert_array_equal(np.rint(points[axis].astype(np.float64) / las.header.scales[0]), counts)
    np.testing.assert_array_equal(points["classification"], las.classification)
    np.testing.assert_array_equal(points["object_id"], las.object_id)
    np.testing.assert_array_equal(points["channel"], las.channel)
    np.testing.assert_array_equal(points["intensity"], las.intensity)
    np.testing.assert_array_equal(points["return_number"], las.return_number)
    np.testing.assert_array_equal(points["range_error"], np.asarray(las["range_error_m"]))
    assert len(set(np.unique(las.classification))) >= 2  # a cable on a seabed: the labels mean something


def test_bag_stamps_are_the_las_times_from_2011_09_14_01_46_25_utc(enu_pass):
    """LAS gps_time 0 is GPS second 1e9; GPS ran 15 s ahead of UTC in 2011, so the pass starts at Unix time
    2011-09-14 01:46:25 UTC. Each point's stamp + time is its LAS gps_time within float32's 0.1 us."""
    _, topics, las = enu_pass
    start_ns = int(datetime(2011, 9, 14, 1, 46, 25, tzinfo=timezone.utc).timestamp()) * 1_000_000_000
    since_start_ns = np.concatenate([(_stamp(m.header) - start_ns) + np.asarray(_points(m)["time"], np.float64) * 1e9
                                     for _, m in topics["/points"]])
    np.testing.assert_allclose(since_start_ns, np.asarray(las.gps_time) * 1e9, rtol=0, atol=100)


def test_bag_timestamps_increase_one_message_per_scan_line(enu_pass):
    """Every topic's stamps increase strictly (log time = header stamp); each message holds one scan line, the
    line of a pulse at t being floor(16 t) for cable_survey's 8 Hz oscillating mirror."""
    _, topics, las = enu_pass
    for topic, messages in topics.items():
        stamps = [t for t, _ in messages]
        assert np.all(np.diff(stamps) > 0), topic
        headers = [m.transforms[0].header if topic.startswith("/tf") else m.header for _, m in messages]
        assert stamps == [_stamp(h) for h in headers], topic
    lines = [np.unique(_points(m)["line"]) for _, m in topics["/points"]]
    assert all(line.size == 1 for line in lines)
    expected = np.unique(np.floor(np.asarray(las.gps_time) * LINES_PER_S))
    np.testing.assert_array_equal(np.concatenate(lines), expected)


def test_odometry_and_tf_span_the_pass_and_follow_the_navigation(enu_pass):
    """/odometry, /ground_truth/odometry and /tf start at or before the first point and end at or after the last;
    their positions plus the local origin are trajectory.csv's estimated and true positions at the same times;
    /tf carries world -> base_link."""
    out, topics, las = enu_pass
    first, last = topics["/points"][0][0], topics["/points"][-1][0] + 1e9 * float(
        _points(topics["/points"][-1][1])["time"].max())
    with open(out / "trajectory.csv", newline="") as fh:
        table = {round(float(row["time_s"]) * 10): row for row in csv.DictReader(fh)}
    origin = las.header.offsets
    for topic, prefix in (("/odometry", "est_"), ("/ground_truth/odometry", "")):
        stamps = [t for t, _ in topics[topic]]
        assert stamps[0] <= first and stamps[-1] >= last
        for stamp, message in topics[topic]:
            row = table[round((stamp - rosbag.PASS_START_UNIX_NS) / 1e8)]
            p = message.pose.pose.position
            np.testing.assert_allclose(np.array([p.x, p.y, p.z]) + origin,
                                       [float(row[f"{prefix}{a}_m"]) for a in "xyz"], atol=2e-6)
            assert message.child_frame_id == "base_link" and message.header.frame_id == "world"
    for (_, tf), (_, odometry) in zip(topics["/tf"], topics["/odometry"]):
        (vehicle,) = tf.transforms
        assert (vehicle.header.frame_id, vehicle.child_frame_id) == ("world", "base_link")
        assert vehicle.transform.translation.x == odometry.pose.pose.position.x
    assert len(topics["/tf"]) == len(topics["/odometry"])


def test_fixed_mount_is_published_once_on_tf_static_transient_local(enu_pass):
    """The lidar's mount on the vehicle does not move: a bag published it on /tf with every 10 Hz tick and never on
    /tf_static, where ROS 2 tools look for fixed frames, and a subscriber joining late saw it
    only at the next tick. Root cause: the writer put both transforms in one TFMessage per pose. The mount now goes
    once to /tf_static, stamped at the pass start, its connection offering the QoS of ROS 2's static broadcaster
    (reliable, transient-local, keep last 1); /tf carries world -> base_link alone."""
    out, topics, _ = enu_pass
    ((stamp, message),) = topics["/tf_static"]
    (lidar,) = message.transforms
    assert (lidar.header.frame_id, lidar.child_frame_id) == ("base_link", "lidar")
    assert stamp == _stamp(lidar.header) == rosbag.PASS_START_UNIX_NS <= min(t for t, _ in topics["/tf"])
    mount = load_scene("cable_survey").scanner.mount_position_m  # forward, left, up: ENU's vehicle axes as they are
    t = lidar.transform.translation
    assert (t.x, t.y, t.z) == pytest.approx(tuple(mount), abs=1e-12)
    assert all(f.child_frame_id != "lidar" for _, m in topics["/tf"] for f in m.transforms)
    with Reader(out / "rosbag") as reader:
        (connection,) = [c for c in reader.connections if c.topic == "/tf_static"]
        (qos,) = connection.ext.offered_qos_profiles
        assert (qos.durability.name, qos.reliability.name, qos.history.name, qos.depth) == (
            "TRANSIENT_LOCAL", "RELIABLE", "KEEP_LAST", 1)


def test_odometry_twist_at_the_track_start_is_the_full_speed(enu_pass):
    """cable_survey runs east along a straight line at its plan speed from t = 0: the true twist, turned into the
    world by the pose's own quaternion, is that speed eastward in plan, nothing northward; in the vehicle frame it
    is mostly forward, nothing to the left (no roll, no yaw turn). Root cause of the bug it pins: the central
    difference at the first tick (t = 0) took the pose at t = -0.05 s, where the track holds the vehicle at its
    start, and gave half the speed; the difference is now one-sided at the track's ends."""
    _, topics, _ = enu_pass
    speed = load_scene("cable_survey").platform.speed_m_s
    for _, m in topics["/ground_truth/odometry"]:
        v = m.twist.twist.linear
        world = _matrix(m.pose.pose.orientation) @ [v.x, v.y, v.z]
        assert world[:2] == pytest.approx([speed, 0.0], abs=1e-6)
        assert v.x > 0.99 * speed and abs(v.y) < 1e-9


def test_ned_bag_turns_the_axes_as_documented(tmp_path, enu_pass):
    """NED (and SQLite storage): a point's (x, y, z) is the ENU bag's (y, x, -z), by hand for the first point
    against the LAS; the vehicle's forward axis keeps its world direction, its left axis becomes -starboard; the
    lidar mount (0.5, 0.2, -0.3) m forward, left, up sits at (0.5, -0.2, 0.3) forward, starboard, down."""
    config = load_scene("cable_survey").with_overrides({"output.rosbag": {"frame": "ned", "storage": "sqlite3"},
                                                        "scanner.mount_position_m": [0.5, 0.2, -0.3]})
    out = tmp_path / "ned"
    run_pass(config, out, PassOptions(max_pulses=600, progress=False, render=False, write_scene=False))
    assert sorted(p.name for p in (out / "rosbag").iterdir()) == ["metadata.yaml", "rosbag.db3"]
    topics = _read_bag(out / "rosbag")
    las = laspy.read(out / "points.las")
    first = _points(topics["/points"][0][1])[0]
    east, north, up = las.x[0] - las.header.offsets[0], las.y[0] - las.header.offsets[1], las.z[0] - las.header.offsets[2]
    assert (first["x"], first["y"], first["z"]) == pytest.approx((north, east, -up), abs=1e-6)
    assert topics["/points"][0][1].header.frame_id == "world_ned"
    _, enu_topics, _ = enu_pass
    for (_, ned), (_, enu) in zip(topics["/odometry"], enu_topics["/odometry"]):
        assert (ned.header.frame_id, ned.child_frame_id) == ("world_ned", "base_link_frd")
        r_ned, r_enu = _matrix(ned.pose.pose.orientation), _matrix(enu.pose.pose.orientation)
        np.testing.assert_allclose(r_ned[:, 0], [r_enu[1, 0], r_enu[0, 0], -r_enu[2, 0]], atol=1e-9)  # forward
        np.testing.assert_allclose(r_ned[:, 1], [-r_enu[1, 1], -r_enu[0, 1], r_enu[2, 1]], atol=1e-9)  # starboard
        p_ned, p_enu = ned.pose.pose.position, enu.pose.pose.position
        assert (p_ned.x, p_ned.y, p_ned.z) == pytest.approx((p_enu.y, p_enu.x, -p_enu.z), abs=1e-9)
    (lidar,) = topics["/tf_static"][0][1].transforms
    assert lidar.child_frame_id == "lidar_frd"
    t = lidar.transform.translation
    assert (t.x, t.y, t.z) == pytest.approx((0.5, -0.2, 0.3))


def _matrix(q):
    """Rotation matrix of a unit quaternion (x, y, z, w), written out."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_bag_messages_do_not_depend_on_chunk_size(tmp_path):
    """A seed fixes the bag's messages bit for bit whatever the chunk size: lines are cut by time, not by chunk."""
    config = load_scene("cable_survey").with_overrides({"output.rosbag": {}})
    bags = []
    for chunk in (500, 1700):
        out = tmp_path / f"chunk{chunk}"
        run_pass(config, out, PassOptions(max_pulses=2000, chunk_pulses=chunk, progress=False, render=False,
                                          write_scene=False))
        with Reader(out / "rosbag") as reader:
            bags.append([(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()])
    assert bags[0] == bags[1] and len(bags[0]) > 10


def test_rosbag_files_are_in_the_pass_plan(tmp_path):
    """A bag in the output folder is part of the pass (a campaign's completeness check reads the plan); one
    written elsewhere (``dir``) is not."""
    out = _pass(tmp_path, pulses=300)
    options = PassOptions(max_pulses=300, progress=False, render=False, write_scene=False)
    files = PassPlan.of(load_scene("cable_survey").with_overrides({"output.rosbag": {}}), options).files
    assert {"rosbag/metadata.yaml", "rosbag/rosbag.mcap"} <= set(files)
    assert all((out / name).is_file() for name in files)
    elsewhere = load_scene("cable_survey").with_overrides({"output.rosbag.dir": str(tmp_path / "bag")})
    assert not any(name.startswith("rosbag") for name in PassPlan.of(elsewhere).files)


def test_run_rosbag_dir_writes_the_bag_there(tmp_path, capsys):
    """``scanner-sim run SCENE --rosbag DIR``: the bag's folder is DIR, its storage file DIR's name."""
    code = main(["run", "cable_survey", "--out", str(tmp_path / "run"), "--rosbag", str(tmp_path / "bag"),
                 "--max-pulses", "300", "--no-render", "--quiet"])
    assert code == 0
    assert sorted(p.name for p in (tmp_path / "bag").iterdir()) == ["bag.mcap", "metadata.yaml"]
    assert not (tmp_path / "run" / "rosbag").exists()
    points = sum(_points(m).size for _, m in _read_bag(tmp_path / "bag")["/points"])
    assert points == laspy.read(tmp_path / "run" / "points.las").header.point_count


@pytest.mark.parametrize(("key", "value", "allowed"), [("frame", "up", "'enu', 'ned'"),
                                                       ("storage", "bag", "'mcap', 'sqlite3'")])
def test_unknown_rosbag_frame_or_storage_is_one_line_exit_2(tmp_path, capsys, key, value, allowed):
    code = main(["run", "cable_survey", "--out", str(tmp_path / "run"), "--max-pulses", "10", "--quiet",
                 "--set", f"output.rosbag.{key}={value}"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert f"output.rosbag.{key}" in err and repr(value) in err and allowed in err
    assert not (tmp_path / "run").exists()


def test_rosbag_dir_inside_the_output_folder_is_refused(tmp_path, capsys):
    code = main(["run", "cable_survey", "--out", str(tmp_path / "run"), "--rosbag", str(tmp_path / "run" / "bag"),
                 "--max-pulses", "10", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "output.rosbag.dir" in err
    assert list(tmp_path.iterdir()) == []  # refused before any lock made a folder


def test_interrupted_bag_leaves_the_previous_bag_whole(tmp_path, monkeypatch):
    """A pass that fails after its bag has taken messages leaves no bag-looking folder: the earlier complete bag
    stays as it was and no hidden folder remains."""
    bag = tmp_path / "bag"
    config = load_scene("cable_survey").with_overrides({"output.rosbag.dir": str(bag)})
    options = PassOptions(max_pulses=1000, progress=False, render=False, write_scene=False)  # 4 lines
    run_pass(config, tmp_path / "run", options)
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    written = []

    def fail_on_second_line(self, records, line):
        written.append(line)
        if len(written) == 2:
            raise OSError(28, "No space left on device")
        return original(self, records, line)

    original = rosbag.RosbagWriter.write_line
    monkeypatch.setattr(rosbag.RosbagWriter, "write_line", fail_on_second_line)
    with pytest.raises(OSError, match="No space"):
        run_pass(config.with_overrides({"survey.seed": 9}), tmp_path / "run", options)
    assert {p.name: p.read_bytes() for p in bag.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag", "run"]  # no hidden leftovers, no lock file


def test_bag_folder_held_by_another_writer_is_refused(tmp_path):
    config = load_scene("cable_survey").with_overrides({"output.rosbag.dir": str(tmp_path / "bag")})
    with OutputLock(tmp_path / "bag"), pytest.raises(OutputBusyError, match="being written by another run"):
        run_pass(config, tmp_path / "run", PassOptions(max_pulses=100, progress=False, render=False))
    assert not (tmp_path / "run").exists() and not (tmp_path / "bag").exists()


def test_bag_folder_holding_other_files_is_refused(tmp_path):
    """A folder with files but no metadata.yaml is not a bag: never replaced."""
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "notes.txt").write_text("mine")
    config = load_scene("cable_survey").with_overrides({"output.rosbag.dir": str(tmp_path / "bag")})
    with pytest.raises(ValueError, match="no metadata.yaml"):
        run_pass(config, tmp_path / "run", PassOptions(max_pulses=100, progress=False, render=False))
    assert (tmp_path / "bag" / "notes.txt").read_text() == "mine"


def test_float32_keeps_every_millimetre_count_within_16384_m():
    """The bag's claim, checked on 1,000,000 random LAS counts up to 2**14 m: float32 of count * 1 mm rounds back
    to the count; just past it, float32's 1.95 mm steps lose about half of them."""
    rng = np.random.default_rng(7)
    limit = int(rosbag.MAX_FLOAT32_EXACT_M * 1000)
    for counts, exact in ((rng.integers(-limit, limit + 1, 1_000_000), True),
                          (rng.integers(limit + 1, 2 * limit, 10_000), False)):
        back = np.rint((counts * 0.001).astype(np.float32).astype(np.float64) / 0.001)
        assert np.all(back == counts) == exact


def test_points_beyond_float32_millimetres_are_refused(tmp_path):
    """float32 keeps 1 mm only within 16,384 m of the local origin: a point farther is refused, not rounded."""
    from scanner_sim.records.point_records import PointRecords

    n = 2
    records = PointRecords(gps_time_s=np.zeros(n), xyz=np.array([[10.0, 0, 0], [20000.0, 0, 0]]),
                           intensity=np.zeros(n, np.uint16), return_number=np.ones(n, np.uint8),
                           number_of_returns=np.ones(n, np.uint8), classification=np.zeros(n, np.uint8),
                           scan_angle_deg=np.zeros(n), channel=np.ones(n, np.uint8), amplitude_lsb=np.zeros(n),
                           snr=np.zeros(n), saturated=np.zeros(n, bool), true_range_m=np.zeros(n),
                           range_error_m=np.zeros(n), incidence_deg=np.zeros(n), object_id=np.zeros(n, np.int32),
                           leg=np.ones(n, np.uint16), pulse_index=np.arange(n))
    with pytest.raises(ValueError, match="20,000 m"), rosbag.RosbagWriter(tmp_path / "bag") as bag:
        bag.write_line(records, 0)
    assert not (tmp_path / "bag").exists()


def test_campaign_pass_keeps_its_rosbag_folder(tmp_path):
    """A campaign's pass (a Dask task) returns its files by name and the campaign writes them into the pass's
    folder. Root cause of the bug it pins: the task read only the top folder's files, so the bag (a folder) was
    dropped and the pass never looked complete (its plan lists rosbag/metadata.yaml)."""
    from scanner_sim.runs.jobs import completed_summary, write_pass
    from scanner_sim.runs.tasks import PassJob, pass_files

    config = load_scene("cable_survey").with_overrides({"output.rosbag": {}})
    job = PassJob("bagged", config, PassOptions(max_pulses=300, progress=False, render=False, write_scene=False))
    write_pass(tmp_path / "bagged", pass_files(job.config, job.options))
    assert completed_summary(tmp_path / "bagged", job) is not None
    points = sum(_points(m).size for _, m in _read_bag(tmp_path / "bagged" / "rosbag")["/points"])
    assert points == laspy.read(tmp_path / "bagged" / "points.las").header.point_count


def test_the_documented_reading_example_gives_the_las_points(enu_pass):
    """docs/outputs.md's example of reading a bag back, run as written on this pass's bag."""
    import re
    from pathlib import Path

    out, _, las = enu_pass
    page = (Path(__file__).resolve().parents[3] / "docs" / "outputs.md").read_text()
    code = re.search(r"### Reading it back\n\n```python\n(.*?)```", page, re.S).group(1)
    names = {}
    exec(code.replace('"out/cable_survey/rosbag"', repr(str(out / "rosbag"))), names)  # noqa: S102 - our own docs
    np.testing.assert_allclose(names["xyz"], np.c_[las.x, las.y, las.z], rtol=0, atol=1e-6)


def test_the_documented_point_fields_are_the_bag_fields(enu_pass):
    """docs/outputs.md's table of PointCloud2 fields names the bag's fields, types and order."""
    import re
    from pathlib import Path

    _, topics, _ = enu_pass
    page = (Path(__file__).resolve().parents[3] / "docs" / "outputs.md").read_text()
    table = page[page.index("### PointCloud2 fields"):page.index("The coordinates are float32")]
    documented = []
    for names, kind in re.findall(r"^\| ([a-z_, ]+) \| ([A-Z0-9]+) \|", table, re.M):
        documented += [(name.strip(), kind) for name in names.split(",")]
    kinds = {1: "INT8", 2: "UINT8", 3: "INT16", 4: "UINT16", 5: "INT32", 6: "UINT32", 7: "FLOAT32", 8: "FLOAT64"}
    cloud = topics["/points"][0][1]
    assert documented == [(f.name, kinds[f.datatype]) for f in cloud.fields]
    assert f"`point_step` {cloud.point_step} bytes" in page


def test_passes_sharing_one_bag_folder_are_refused(tmp_path):
    """Many passes (a campaign, a coverage study) with one ``output.rosbag.dir`` would each replace the bag before:
    refused in one line before any pass runs."""
    from scanner_sim.config import ConfigError
    from scanner_sim.runs.jobs import check_jobs
    from scanner_sim.runs.tasks import PassJob

    config = load_scene("cable_survey").with_overrides({"output.rosbag.dir": str(tmp_path / "bag")})
    jobs = [PassJob(f"seed{s}", config.with_overrides({"survey.seed": s})) for s in (1, 2)]
    with pytest.raises(ConfigError, match=r"output.rosbag.dir = .*the 2 passes would each replace"):
        check_jobs(jobs)


def test_scan_line_is_a_revolution_a_sweep_or_a_period():
    """By hand: a continuous mirror at 20 Hz starts a line every 50 ms; an oscillating one at 8 Hz every 62.5 ms
    (each half period, both directions); a static one every period of its scan rate."""
    from scanner_sim.motion.scanner import Scanner

    t = np.array([0.0, 0.0499, 0.0501, 0.0624, 0.0626, 0.1249, 0.1251])
    np.testing.assert_array_equal(Scanner(mode="continuous", scan_rate_hz=20.0).line_index(t), [0, 0, 1, 1, 1, 2, 2])
    np.testing.assert_array_equal(Scanner(mode="oscillating", scan_rate_hz=8.0).line_index(t), [0, 0, 0, 0, 1, 1, 2])
    np.testing.assert_array_equal(Scanner(mode="static", scan_rate_hz=8.0).line_index(t), [0, 0, 0, 0, 0, 0, 1])


def test_bag_metadata_names_frame_origin_epoch_and_pass(enu_pass):
    """metadata.yaml's custom_data holds what docs/outputs.md lists: the frame, the local origin (the LAS offset),
    the coordinate scale, the pass start and the pass's metadata (scene, seed...)."""
    import json

    import yaml

    out, topics, las = enu_pass
    info = yaml.safe_load((out / "rosbag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    custom = info["custom_data"]
    assert custom["muls_scanner.frame"] == "enu"
    np.testing.assert_array_equal(json.loads(custom["muls_scanner.local_origin_m"]), las.header.offsets)
    assert float(custom["muls_scanner.coordinate_scale_m"]) == las.header.scales[0] == 0.001
    assert int(custom["muls_scanner.pass_start_unix_ns"]) == 1_315_964_785_000_000_000
    meta = json.loads(custom["muls_scanner.pass_metadata"])
    assert meta["scene"] == "cable_survey" and meta["seed"] == load_scene("cable_survey").survey.seed
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert counts == {topic: len(messages) for topic, messages in topics.items()}
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"


@pytest.mark.parametrize(("frame", "pitch_sign"), [("enu", -1.0), ("ned", 1.0)])
def test_odometry_angular_rate_is_the_roll_and_pitch_rates_by_hand(tmp_path, frame, pitch_sign):
    """The vehicle heads east (yaw 0) and rolls 5 deg every 2 s and pitches 3 deg every 3 s (no terrain pitch):
    R = Ry(-p) Rx(r), so the angular rate in the vehicle frame is (r', -p' cos r, p' sin r) in x forward, y left,
    z up, and (r', p' cos r, -p' sin r) in x forward, y starboard, z down (roll starboard-down and pitch nose-up
    positive about the FRD axes). The central difference over 0.1 s keeps sin(w h)/(w h) > 0.995 of the rate."""
    attitude = {"roll_amplitude_deg": 5.0, "roll_period_s": 2.0, "pitch_amplitude_deg": 3.0, "pitch_period_s": 3.0,
                "follow_terrain_pitch": False}
    config = load_scene("cable_survey").with_overrides({"output.rosbag": {"frame": frame}, "platform.attitude": attitude})
    out = tmp_path / frame
    run_pass(config, out, PassOptions(max_pulses=5000, progress=False, render=False, write_scene=False))
    odometry = _read_bag(out / "rosbag")["/ground_truth/odometry"]
    assert len(odometry) == 11
    for stamp, message in odometry:
        t = (stamp - rosbag.PASS_START_UNIX_NS) / 1e9
        r = np.radians(5.0) * np.sin(np.pi * t)
        r_rate, p_rate = np.radians(5.0) * np.pi * np.cos(np.pi * t), np.radians(3.0) * 2 * np.pi / 3 * np.cos(
            2 * np.pi * t / 3)
        w = message.twist.twist.angular
        expected = [r_rate, pitch_sign * p_rate * np.cos(r), -pitch_sign * p_rate * np.sin(r)]
        np.testing.assert_allclose([w.x, w.y, w.z], expected, rtol=0, atol=2e-3)
