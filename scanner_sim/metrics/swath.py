"""Swath-to-swath consistency between overlapping survey lines: the standard mapping QA figure.

Where two lines of a lawnmower see the same seabed, their points should agree. For every point of one line
whose nearest neighbour in the other line lies within ``overlap_m`` (the overlap), the cloud-to-cloud (C2C)
distance to that neighbour is taken with open3d (an optional extra: ``pip install "muls-scanner[open3d]"``),
and so is the signed vertical difference between them. Reported per pair of adjacent lines: the overlap's
size, the median and 95th percentile of the C2C distance, and the mean and RMS vertical difference (a
bias between lines shows as a mean, noise as RMS).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from scanner_sim.records.point_records import PointRecords

#: Largest nearest-neighbour distance [m] for a point to count as in the overlap of two lines.
OVERLAP_M = 0.5


def open3d():
    """The open3d module, or an ImportError that names the extra to install."""
    try:
        import open3d as o3d
    except (ImportError, OSError) as exc:  # OSError: a system library it loads (libusb) is missing
        raise ImportError("this needs open3d: pip install 'muls-scanner[open3d]' (and, on Debian, "
                          f"apt-get install libusb-1.0-0) [{exc}]") from None
    return o3d


@dataclass(frozen=True)
class SwathPair:
    """Agreement of two overlapping lines (legs ``leg_a`` and ``leg_b``): points of ``leg_a`` in the overlap,
    C2C distance median and 95th percentile [m], vertical difference a - b mean and RMS [m]."""

    leg_a: int
    leg_b: int
    overlap_points: int
    c2c_median_m: float
    c2c_p95_m: float
    dz_mean_m: float
    dz_rms_m: float


def survey_lines(points: PointRecords, min_points: int = 1000) -> list[int]:
    """Legs that are survey lines: on a lawnmower the odd legs (the even ones are the turns), with at least
    ``min_points`` points."""
    legs, counts = np.unique(points.leg, return_counts=True)
    return [int(leg) for leg, n in zip(legs, counts) if leg % 2 == 1 and n >= min_points]


def compare_lines(points: PointRecords, leg_a: int, leg_b: int, overlap_m: float = OVERLAP_M) -> SwathPair:
    """The agreement of line ``leg_a`` with line ``leg_b`` where they overlap (valid, non-noise points)."""
    o3d = open3d()
    a = points.xyz[(points.leg == leg_a) & (points.object_id >= 0)]
    b = points.xyz[(points.leg == leg_b) & (points.object_id >= 0)]
    if not len(a) or not len(b):
        return SwathPair(leg_a, leg_b, 0, *(float("nan"),) * 4)
    origin = b.mean(axis=0)  # a local frame keeps the float64 differences small
    search = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(b - origin))
    search.knn_index()
    nearest, d2 = search.knn_search(o3d.core.Tensor(a - origin), 1)
    nearest, c2c = nearest.numpy()[:, 0], np.sqrt(d2.numpy()[:, 0])  # C2C: distance to the nearest point
    inside = c2c <= overlap_m
    dz = a[inside, 2] - b[nearest[inside], 2]
    pick = c2c[inside]
    return SwathPair(leg_a, leg_b, int(inside.sum()),
                     float(np.median(pick)) if pick.size else float("nan"),
                     float(np.percentile(pick, 95)) if pick.size else float("nan"),
                     float(dz.mean()) if dz.size else float("nan"),
                     float(np.sqrt(np.mean(dz**2))) if dz.size else float("nan"))


def swath_consistency(points: PointRecords, overlap_m: float = OVERLAP_M) -> list[dict]:
    """Every pair of adjacent survey lines compared (:class:`SwathPair` as dicts, JSON-ready)."""
    lines = survey_lines(points)
    return [asdict(compare_lines(points, a, b, overlap_m)) for a, b in zip(lines, lines[1:])]
