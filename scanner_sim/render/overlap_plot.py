"""The overlap factor against distance: a ray-cast estimate over the analytic curve of MULS Eq. 11."""

from __future__ import annotations

import numpy as np

from scanner_sim.render.figure_png import figure_to_png


def plot_overlap(
    path_png,
    distance_m,
    raycast,
    analytic,
    *,
    title: str | None = None,
    raycast_label: str = "ray-cast (sub-rays in FOV and visible)",
    analytic_label: str = "MULS Eq. 11",
    dense_distance_m=None,
    dense_analytic=None,
) -> None:
    """Overlap factor against distance: the ray-cast estimate over the analytic Eq. 11 curve.

    Parameters
    ----------
    distance_m : (n,) float [m]
        Distance to the flat target.
    raycast : (n,) float [1]
        Fraction of beam energy passing the receiver check (markers); NaN entries are skipped.
    analytic : (n,) float [1]
        Eq. 11 overlap at the same distances (line).
    dense_distance_m, dense_analytic : (m,) float, optional
        A finer Eq. 11 curve to draw instead of ``analytic`` (which then only checks shapes).
    """
    d = np.asarray(distance_m, dtype=np.float64)
    if d.ndim != 1:
        raise ValueError(f"distance_m: shape {d.shape} is not allowed; expected (n,)")
    r = np.asarray(raycast, dtype=np.float64)
    a = np.asarray(analytic, dtype=np.float64)
    for name, arr in (("raycast", r), ("analytic", a)):
        if arr.shape != d.shape:
            raise ValueError(f"{name}: shape {arr.shape} is not allowed; expected {d.shape}")
    if (dense_distance_m is None) != (dense_analytic is None):
        raise ValueError("dense_distance_m and dense_analytic: give both or neither")
    if dense_distance_m is not None:
        curve_d = np.asarray(dense_distance_m, dtype=np.float64)
        curve_a = np.asarray(dense_analytic, dtype=np.float64)
        if curve_d.ndim != 1 or curve_a.shape != curve_d.shape:
            raise ValueError(
                f"dense_distance_m {curve_d.shape} / dense_analytic {curve_a.shape}: expected two (m,) arrays"
            )
    else:
        curve_d, curve_a = d, a

    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.5), dpi=110, layout="constrained")
    ax = fig.subplots()
    ax.plot(curve_d, curve_a, "-", color="k", lw=1.5, label=analytic_label)
    ax.plot(d, r, "o", ms=4, color="tab:orange", label=raycast_label)
    ax.set_xlabel("distance to target [m]")
    ax.set_ylabel("overlap factor O(z)")
    ax.set_ylim(-0.02, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    if title:
        ax.set_title(title)
    figure_to_png(fig, path_png)
