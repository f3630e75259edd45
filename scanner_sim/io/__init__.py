"""Writers and readers of a survey pass's output files (``docs/outputs.md``), one module per format.

- :func:`atomic_path` (:mod:`muls.infra.atomic`), the atomic write every writer uses.
- :mod:`~scanner_sim.io.las`: ``points.las``, LAS 1.4 format 6 with extra dimensions, streamed by
  :class:`LasWriter`; the layout follows the :class:`~scanner_sim.records.point_records.PointRecords` declarations.
- :mod:`~scanner_sim.io.dropouts`: ``dropouts.npz``, streamed by :class:`DropoutWriter`.
- :mod:`~scanner_sim.io.ply`: ``scene.ply``, the labelled truth meshes.
- :mod:`~scanner_sim.io.summary`: ``summary.json``.
- :mod:`~scanner_sim.io.tables`: ``trajectory.csv``, ``waveforms.npz``, ``coverage_grid.npz``, text files.
- :mod:`~scanner_sim.io.gis`: Cloud-Optimized GeoTIFF and GeoJSON in a map CRS (a scene with a ``crs``).
- :mod:`~scanner_sim.io.rosbag`: a pass as a ROS 2 bag folder, streamed by :class:`~scanner_sim.io.rosbag.RosbagWriter`
  (not re-exported: import it from its module).
"""

from muls.infra.atomic import atomic_path
from scanner_sim.io.dropouts import DropoutWriter, read_dropouts_npz, write_dropouts_npz
from scanner_sim.io.gis import write_cog, write_geojson
from scanner_sim.io.las import (
    EXTRA_DIMENSIONS,
    LAS_POINT_FORMAT,
    LAS_SCALE_M,
    LAS_VERSION,
    LOCAL_ENGINEERING_WKT,
    SCAN_ANGLE_UNIT_DEG,
    LasWriter,
    read_las,
    read_las_metadata,
    scan_angle_to_las,
    write_las,
)
from scanner_sim.io.ply import read_scene_ply, write_scene_ply
from scanner_sim.io.summary import write_summary_json
from scanner_sim.io.tables import (
    read_coverage_grid_npz,
    read_trajectory_csv,
    read_waveforms_npz,
    write_coverage_grid_npz,
    write_text,
    write_trajectory_csv,
    write_waveforms_npz,
)

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
    "write_cog",
    "write_coverage_grid_npz",
    "write_dropouts_npz",
    "write_geojson",
    "write_las",
    "write_scene_ply",
    "write_summary_json",
    "write_text",
    "write_trajectory_csv",
    "write_waveforms_npz",
]
