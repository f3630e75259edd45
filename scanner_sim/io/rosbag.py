"""A pass as a ROS 2 bag (rosbag2, MCAP or SQLite storage), written with ``rosbags``: no ROS install needed.

Topics (``docs/outputs.md``): ``/points`` (``sensor_msgs/msg/PointCloud2``, one message per scan line, the points
in the world frame), ``/odometry`` and ``/ground_truth/odometry`` (``nav_msgs/msg/Odometry``: the navigation's
estimate and the true pose), ``/tf`` (``tf2_msgs/msg/TFMessage``: world -> vehicle from the navigation) and
``/tf_static`` (vehicle -> lidar, the fixed mount, once, offered transient-local as ROS 2's static broadcaster does).
Axes follow REP 103 (ENU world, vehicle x forward, y left, z up) or, for ``ned``, the
marine convention (NED world, vehicle x forward, y starboard, z down).

Coordinates: float32 metres from the scene's local origin (the LAS header offset), on the LAS's millimetre grid,
so a bag point plus the origin is the LAS point. Time: the pass starts at the instant the LAS calls GPS second
1e9, written as ROS time (Unix nanoseconds, :data:`PASS_START_UNIX_NS`).

The bag is written into a locked hidden folder beside its final one and swapped in whole
(:class:`~scanner_sim.io.run_dir.RunDirectory`, complete when it holds ``metadata.yaml``).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from muls.infra.atomic import PathLike, StreamingWriter
from scanner_sim.io.las import LAS_SCALE_M
from scanner_sim.io.run_dir import RunDirectory
from scanner_sim.io.summary import jsonable
from scanner_sim.records.point_records import PointRecords

__all__ = ["BAG_FRAMES", "BAG_STORAGES", "PASS_START_UNIX_NS", "POINT_FIELDS", "ROSBAG_NAME", "BagFrame",
           "RosbagWriter", "bag_files", "stamp_ns", "typestore"]

#: Unix time [ns] of the pass start: GPS second 1e9 (LAS ``gps_time`` 0, ``docs/outputs.md``), 1980-01-06 being
#: Unix second 315,964,800 and GPS time 15 s ahead of UTC in September 2011: 2011-09-14 01:46:25 UTC.
PASS_START_UNIX_NS = (315_964_800 + 1_000_000_000 - 15) * 1_000_000_000
#: Farthest a point may lie from the local origin [m] along any axis: below 2**14 m float32's step is at most
#: 0.98 mm, so its rounding error (half a step, 0.49 mm) stays under half the LAS's 1 mm and the bag's float32
#: rounds back to the LAS's millimetre count.
MAX_FLOAT32_EXACT_M = 16384.0
#: rosbag2 storages: name -> suffix of the storage file.
BAG_STORAGES = {"mcap": ".mcap", "sqlite3": ".db3"}
#: The file that makes a bag folder complete (written last by rosbags).
BAG_MARKER = "metadata.yaml"
#: The bag's folder in the output folder, unless the scene's ``output.rosbag.dir`` puts it elsewhere.
ROSBAG_NAME = "rosbag"


def bag_files(folder: str, storage: str) -> tuple[str, str]:
    """The files of a complete bag in ``folder`` (its name), as paths under the folder's parent."""
    return f"{folder}/{BAG_MARKER}", f"{folder}/{folder}{BAG_STORAGES[storage]}"


@functools.cache
def typestore():
    """The message definitions written, ROS 2 Jazzy's (their type hashes go into the bag). rosbags is imported
    here, on a bag's first use, so a pass without a bag does not pay for it (0.07 s measured)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def static_qos() -> list:
    """The QoS ROS 2's static transform broadcaster offers on /tf_static (tf2_ros ``StaticBroadcasterQoS``): reliable,
    transient-local, keep the last 1, so a late subscriber still receives the mount; durations infinite as ``ros2 bag
    record`` writes them."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    infinite = QosTime(2147483647, 4294967295)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, infinite, infinite,
                QosLiveliness.AUTOMATIC, infinite, avoid_ros_namespace_conventions=False)]


def _msg(kind: str, **fields):
    """A message of ROS type ``kind`` (``std_msgs/msg/Header``) with ``fields``."""
    return typestore().types[kind](**fields)


#: sensor_msgs/msg/PointField datatype constants.
_UINT8, _INT32, _UINT32, _FLOAT32 = 2, 5, 6, 7
#: PointCloud2 fields: name -> (numpy dtype, PointField datatype, meaning).
POINT_FIELDS = {
    "x": (np.float32, _FLOAT32, "[m] world frame, from the local origin"),
    "y": (np.float32, _FLOAT32, "[m]"),
    "z": (np.float32, _FLOAT32, "[m]"),
    "intensity": (np.float32, _FLOAT32, "LAS intensity (0..65535)"),
    "time": (np.float32, _FLOAT32, "[s] pulse emission after the message stamp"),
    "line": (np.uint32, _UINT32, "scan line of the pass"),
    "object_id": (np.int32, _INT32, "scene object hit, -1 none"),
    "range_error": (np.float32, _FLOAT32, "[m] measured - true range, NaN without truth"),
    "return_number": (np.uint8, _UINT8, "1-based, nearest first"),
    "classification": (np.uint8, _UINT8, "ground-truth class (LAS classification)"),
    "channel": (np.uint8, _UINT8, "detection channel"),
}
#: The points' layout: every field at its natural alignment, 36 bytes a point.
_POINT_DTYPE = np.dtype([(name, dtype) for name, (dtype, _, _) in POINT_FIELDS.items()], align=True)


@dataclass(frozen=True)
class BagFrame:
    """A frame convention: the frame names, and the axes turning the scene's world (x east, y north, z up) and
    vehicle (x forward, y left, z up) vectors into this convention's (``world_axes``, ``body_axes``: (3, 3),
    proper rotations, their own inverses)."""

    world: str
    vehicle: str
    lidar: str
    world_axes: np.ndarray
    body_axes: np.ndarray

    def pose(self, position_m: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (n, 3) [m] and vehicle-to-world rotations (n, 3, 3) of the scene's axes in this convention's:
        p' = W p and R' = W R B."""
        return position_m @ self.world_axes.T, self.world_axes @ rotation @ self.body_axes


#: ``enu``: REP 103. ``ned``: the marine one (x north, y east, z down; vehicle x forward, y starboard, z down).
BAG_FRAMES = {
    "enu": BagFrame("world", "base_link", "lidar", np.eye(3), np.eye(3)),
    "ned": BagFrame("world_ned", "base_link_frd", "lidar_frd",
                    np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]), np.diag([1.0, -1.0, -1.0])),
}


def stamp_ns(time_s) -> np.ndarray:
    """ROS time [ns since 1970-01-01 UTC] (n,) int64 of ``time_s`` (n,) [s from the pass start]."""
    return PASS_START_UNIX_NS + np.rint(np.asarray(time_s, np.float64) * 1e9).astype(np.int64)


def _header(stamp: int, frame_id: str):
    time = _msg("builtin_interfaces/msg/Time", sec=int(stamp // 1_000_000_000), nanosec=int(stamp % 1_000_000_000))
    return _msg("std_msgs/msg/Header", stamp=time, frame_id=frame_id)


def _vector(v, kind: str = "geometry_msgs/msg/Vector3"):
    return _msg(kind, x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quaternion(q):
    return _msg("geometry_msgs/msg/Quaternion", x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


class RosbagWriter(StreamingWriter):
    """A ROS 2 bag, written scan line by scan line and pose by pose, swapped into ``path`` (a folder) when closed.

    frame: ``enu`` or ``ned`` (:data:`BAG_FRAMES`); storage: ``mcap`` or ``sqlite3``; offset_m (3,) [m]: the
    local origin the coordinates are taken from (the LAS offset); scale_m [m]: the LAS's grid;
    lidar_offset_m (3,) [m]: the scanner's mount in the vehicle frame (x forward, y left, z up); metadata: the
    pass's (JSON), kept in the bag's ``custom_data``.
    """

    def __init__(self, path: PathLike, *, frame: str = "enu", storage: str = "mcap", offset_m=(0.0, 0.0, 0.0),
                 scale_m: float = LAS_SCALE_M, lidar_offset_m=(0.0, 0.0, 0.0), metadata: dict | None = None):
        if frame not in BAG_FRAMES:
            raise ValueError(f"rosbag frame = {frame!r}: not allowed; use one of {', '.join(BAG_FRAMES)}")
        if storage not in BAG_STORAGES:
            raise ValueError(f"rosbag storage = {storage!r}: not allowed; use one of {', '.join(BAG_STORAGES)}")
        self.path, self.frame, self.storage = Path(path), BAG_FRAMES[frame], storage
        self.offset_m, self.scale_m = np.asarray(offset_m, np.float64), float(scale_m)
        self.lidar_offset_m = np.asarray(lidar_offset_m, np.float64) @ self.frame.body_axes.T
        self.custom = {"muls_scanner.frame": frame, "muls_scanner.local_origin_m": json.dumps(self.offset_m.tolist()),
                       "muls_scanner.coordinate_scale_m": repr(self.scale_m),
                       "muls_scanner.pass_start_unix_ns": str(PASS_START_UNIX_NS),
                       "muls_scanner.pass_metadata": json.dumps(jsonable(metadata or {}), sort_keys=True)}
        self._run: RunDirectory | None = None
        self._bag = None  # the rosbags Writer while open
        self._topics: dict = {}
        self.point_count = 0

    def open(self) -> None:
        """Lock the bag folder and start the bag in its hidden sibling."""
        from rosbags.rosbag2 import StoragePlugin, Writer

        self._run = RunDirectory(self.path, complete_marker=BAG_MARKER)
        hidden = self._run.open().path
        try:
            self._bag = Writer(hidden / self.path.name, version=Writer.VERSION_LATEST,
                               storage_plugin=StoragePlugin[self.storage.upper()])
            for key, value in self.custom.items():
                self._bag.set_custom_data(key, value)
            self._bag.open()
            for topic, kind in (("/points", "sensor_msgs/msg/PointCloud2"), ("/odometry", "nav_msgs/msg/Odometry"),
                                ("/ground_truth/odometry", "nav_msgs/msg/Odometry"), ("/tf", "tf2_msgs/msg/TFMessage"),
                                ("/tf_static", "tf2_msgs/msg/TFMessage")):
                qos = static_qos() if topic == "/tf_static" else ()
                self._topics[topic] = (self._bag.add_connection(topic, kind, typestore=typestore(),
                                                                offered_qos_profiles=qos), kind)
            self._write("/tf_static", PASS_START_UNIX_NS, self._mount(PASS_START_UNIX_NS))
        except BaseException:
            self.abort()
            raise

    def _write(self, topic: str, stamp: int, message) -> None:
        connection, kind = self._topics[topic]
        self._bag.write(connection, int(stamp), typestore().serialize_cdr(message, kind))

    def write_line(self, records: PointRecords, line: int) -> None:
        """One scan line's points (in pass order) as one PointCloud2, stamped at its first pulse's emission.
        Raises ValueError for a point farther than :data:`MAX_FLOAT32_EXACT_M` from the local origin."""
        counts = np.rint((records.xyz - self.offset_m) / self.scale_m)  # the LAS's own counts (io/las.py)
        local_m = counts * self.scale_m
        if np.abs(local_m).max(initial=0.0) > MAX_FLOAT32_EXACT_M:
            raise ValueError(f"rosbag: a point lies {np.abs(local_m).max():,.0f} m from the scene's local origin; "
                             f"float32 coordinates keep the LAS's millimetre only within {MAX_FLOAT32_EXACT_M:,.0f} m")
        first_s = float(records.gps_time_s.min())
        stamp = int(stamp_ns([first_s])[0])
        points = np.zeros(len(records), _POINT_DTYPE)
        xyz = local_m @ self.frame.world_axes.T
        points["x"], points["y"], points["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        points["intensity"] = records.intensity
        points["time"] = records.gps_time_s - first_s
        points["line"] = line
        points["return_number"] = records.return_number
        points["classification"] = records.classification
        points["object_id"] = records.object_id
        points["channel"] = records.channel
        points["range_error"] = records.range_error_m
        fields = [_msg("sensor_msgs/msg/PointField", name=name, offset=_POINT_DTYPE.fields[name][1], datatype=datatype,
                       count=1) for name, (_, datatype, _) in POINT_FIELDS.items()]
        message = _msg("sensor_msgs/msg/PointCloud2",
            header=_header(stamp, self.frame.world), height=1, width=len(points), fields=fields, is_bigendian=False,
            point_step=_POINT_DTYPE.itemsize, row_step=_POINT_DTYPE.itemsize * len(points),
            data=points.view(np.uint8), is_dense=True)
        self._write("/points", stamp, message)
        self.point_count += len(records)

    def write_poses(self, time_s, position_m, rotation, velocity_m_s, angular_rad_s, truth: bool) -> None:
        """Odometry at ``time_s`` (n,) [s]: positions (n, 3) [m] and vehicle-to-world rotations (n, 3, 3) in the
        scene's world, velocity (n, 3) [m/s] in the world and angular rate (n, 3) [rad/s] in the vehicle frame.
        The navigation's (``truth`` False) also gives /tf; the truth goes to /ground_truth/odometry."""
        from scipy.spatial.transform import Rotation  # here: scipy.spatial costs a pass without a bag 0.1 s

        position, turn = self.frame.pose(np.asarray(position_m) - self.offset_m, rotation)
        quaternions = Rotation.from_matrix(turn).as_quat()  # (x, y, z, w), scalar last as ROS has it
        linear = np.einsum("nji,nj->ni", turn, np.asarray(velocity_m_s) @ self.frame.world_axes.T)  # R'^T v'
        angular = np.asarray(angular_rad_s) @ self.frame.body_axes.T
        covariance = np.zeros(36)  # not estimated: the navigation's errors are in trajectory.csv
        for t, p, q, v, w in zip(stamp_ns(time_s), position, quaternions, linear, angular):
            pose = _msg("geometry_msgs/msg/Pose", position=_vector(p, "geometry_msgs/msg/Point"),
                        orientation=_quaternion(q))
            twist = _msg("geometry_msgs/msg/Twist", linear=_vector(v), angular=_vector(w))
            odometry = _msg("nav_msgs/msg/Odometry", header=_header(t, self.frame.world), child_frame_id=self.frame.vehicle,
                            pose=_msg("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=covariance),
                            twist=_msg("geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=covariance))
            self._write("/ground_truth/odometry" if truth else "/odometry", t, odometry)
            if not truth:
                self._write("/tf", t, self._vehicle_transform(t, p, q))

    def _vehicle_transform(self, stamp: int, position: np.ndarray, quaternion: np.ndarray):
        """/tf at ``stamp``: world -> vehicle, the navigation's pose."""
        frame = self.frame
        vehicle = _msg("geometry_msgs/msg/TransformStamped", header=_header(stamp, frame.world),
                       child_frame_id=frame.vehicle, transform=_msg("geometry_msgs/msg/Transform",
                                                                    translation=_vector(position),
                                                                    rotation=_quaternion(quaternion)))
        return _msg("tf2_msgs/msg/TFMessage", transforms=[vehicle])

    def _mount(self, stamp: int):
        """/tf_static: vehicle -> lidar, the fixed mount (the lidar's axes are the vehicle's)."""
        frame = self.frame
        lidar = _msg("geometry_msgs/msg/TransformStamped", header=_header(stamp, frame.vehicle),
                     child_frame_id=frame.lidar, transform=_msg("geometry_msgs/msg/Transform",
                                                                translation=_vector(self.lidar_offset_m),
                                                                rotation=_quaternion((0.0, 0.0, 0.0, 1.0))))
        return _msg("tf2_msgs/msg/TFMessage", transforms=[lidar])

    def close(self) -> None:
        """Finish the bag (its index and metadata.yaml) and swap it in under ``path``."""
        if self._bag is None:
            return
        try:
            self._bag.close()
            inner = self._bag.path
            self._bag = None
            for name in os.listdir(inner):  # the bag's files up into the hidden folder, which becomes ``path``
                os.rename(inner / name, inner.parent / name)
            inner.rmdir()
        except BaseException:
            self.abort()
            raise
        run, self._run = self._run, None
        run.commit()

    def abort(self) -> None:
        """Drop the unfinished bag; ``path`` keeps what it held."""
        bag, self._bag = self._bag, None
        if bag is not None:
            with contextlib.suppress(Exception):
                bag.abort()
        run, self._run = self._run, None
        if run is not None:
            run.abort()
