"""coverage_map.png: the plan cells coloured covered or missed by cause, cells with no seabed data apart, cable
centrelines and objects drawn over them (:mod:`scanner_sim.metrics.coverage`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from scanner_sim.render.plan_map import COVERAGE_COLOURS, NO_SEABED_COLOUR, finish_plan_map


def plot_coverage_map(path_png, state, extent_m, gap_causes: Sequence[str], *, lines=(), markers=(),
                      title: str | None = None, no_seabed=None) -> None:
    """Plan map of coverage cells to a PNG.

    state : (ny, nx) int, row = y: -2 not reached, -1 covered, k >= 0 missed for ``gap_causes[k]``.
    extent_m : (x_min, x_max, y_min, y_max) [m] of the grid.
    lines : [(name, (n, 2) xy [m])] drawn over the cells (cable centrelines).
    markers : [(name, (2,) xy [m])] marked and named (mines, objects).
    no_seabed : (ny, nx) bool or None: cells with no seabed data, drawn in :data:`NO_SEABED_COLOUR` over the rest.
    The legend lists covered and every cause present, with its area share of the reached cells.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    state = np.asarray(state)
    if state.ndim != 2:
        raise ValueError(f"state: shape {state.shape} is not allowed; expected (ny, nx)")
    names = ["not_reached", "covered", *gap_causes]
    unknown = [n for n in names if n not in COVERAGE_COLOURS]
    if unknown:
        raise ValueError(f"gap_causes: {unknown} have no colour; known: {sorted(COVERAGE_COLOURS)}")
    codes = state.astype(np.int64) + 2
    x0, x1, y0, y1 = (float(v) for v in extent_m)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig = Figure(figsize=(10.0, float(np.clip(7.0 * aspect + 1.4, 3.0, 12.0))), dpi=110)  # the legend takes ~3 in
    ax = fig.add_subplot()
    ax.imshow(codes, origin="lower", extent=(x0, x1, y0, y1), cmap=ListedColormap([COVERAGE_COLOURS[n] for n in names]),
              vmin=-0.5, vmax=len(names) - 0.5, interpolation="nearest")
    gaps = np.asarray(no_seabed, bool) if no_seabed is not None else np.zeros(state.shape, bool)
    if gaps.any():
        ax.imshow(np.ma.masked_where(~gaps, np.ones(state.shape)), origin="lower", extent=(x0, x1, y0, y1),
                  cmap=ListedColormap([NO_SEABED_COLOUR]), interpolation="nearest")
    for name, xy in lines:
        xy = np.asarray(xy, float)
        ax.plot(xy[:, 0], xy[:, 1], color="black", lw=0.8, alpha=0.8)
        ax.annotate(name, xy[0], fontsize=8, xytext=(3, 3), textcoords="offset points")
    for name, xy in markers:
        ax.plot(*xy, marker="x", color="black", ms=7, mew=1.5)
        ax.annotate(name, xy, fontsize=8, xytext=(5, 5), textcoords="offset points")
    reached = max(int((codes >= 1).sum()), 1)
    counts = np.bincount(codes.ravel(), minlength=len(names))
    handles = [Patch(facecolor=COVERAGE_COLOURS[n], edgecolor="grey", label=f"{n.replace('_', ' ')} "
                     f"{counts[k] / reached:.1%}") for k, n in enumerate(names) if k == 1 or (k >= 2 and counts[k])]
    handles.append(Patch(facecolor=COVERAGE_COLOURS["not_reached"], edgecolor="grey", label="not reached by the scan"))
    if gaps.any():
        handles.append(Patch(facecolor=NO_SEABED_COLOUR, edgecolor="grey", label="no seabed data"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    finish_plan_map(fig, ax, path_png, title)
