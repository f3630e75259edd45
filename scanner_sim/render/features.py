"""features.png: the feature-detection pass in plan, each cube drawn where it stands, green when detected, red when
missed though reached, grey when no pulse reached it and purple when another object hid it, with its size and the
valid soundings it got, over the cells the scan covered."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from scanner_sim.render.plan_map import COVERAGE_COLOURS, finish_plan_map

DETECTED_COLOUR = "#1a9850"
MISSED_COLOUR = "#d73027"
#: Cubes no pulse reached, apart from the missed ones: beyond the scan's reach, or hidden by another object.
UNREACHED_COLOURS = {"not_reached": "#bdbdbd", "shadowed": "#6a51a3"}


def _square(x: float, y: float, size: float, heading_deg: float) -> np.ndarray:
    """(5, 2) corners of a square of ``size`` [m] centred at (x, y), turned by ``heading_deg`` (closed)."""
    a = math.radians(heading_deg)
    r = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    unit = 0.5 * size * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], float)
    return unit @ r.T + [x, y]


def _apart(cubes: dict) -> str:
    """The cubes of one size no pulse reached or another object hid, e.g. " (1 shadowed)"."""
    apart = [f"{cubes[k]} {k.replace('_', ' ')}" for k in ("not_reached", "shadowed") if cubes[k]]
    return f" ({', '.join(apart)})" if apart else ""


def plot_feature_detection(path_png, grid_npz: Path, result: dict, *, title: str | None = None) -> None:
    """Plan map of the pass's coverage cells (``grid_npz``: coverage_grid.npz) with the placed cubes of ``result``
    (features.json's content) drawn and marked detected or missed."""
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    from scanner_sim.io.tables import read_coverage_grid_npz

    grid = read_coverage_grid_npz(grid_npz)
    state = grid["state"]
    ny, nx = state.shape
    cell = float(grid["cell_m"])
    x0, y0 = (float(v) for v in grid["origin_m"])
    extent = (x0, x0 + nx * cell, y0, y0 + ny * cell)
    aspect = (extent[3] - extent[2]) / max(extent[1] - extent[0], 1e-9)
    fig = Figure(figsize=(10.0, float(np.clip(7.0 * aspect + 2.0, 3.5, 12.0))), dpi=110)
    ax = fig.add_subplot()
    shade = np.where(state == -2, 0, np.where(state == -1, 1, 2))
    ax.imshow(shade, origin="lower", extent=extent, interpolation="nearest", vmin=-0.5, vmax=2.5,
              cmap=ListedColormap([COVERAGE_COLOURS["not_reached"], "#b8e0dc", "#d9d9d9"]))
    soundings = {o["name"]: o for o in result["objects"]}
    for p in result["placements"]:
        o = soundings[p["name"]]
        colour = DETECTED_COLOUR if o["detected"] else UNREACHED_COLOURS.get(o["gap_cause"], MISSED_COLOUR)
        corners = _square(p["x_m"], p["y_m"], p["size_m"], p["heading_deg"])
        ax.fill(corners[:, 0], corners[:, 1], facecolor=colour, edgecolor="black", lw=0.6, alpha=0.85)
        ax.annotate(f"{p['size_m']:g} m: {o['valid_points']}", (p["x_m"], p["y_m"] + 0.5 * p["size_m"]),
                    fontsize=7, ha="center", va="bottom", xytext=(0, 2), textcoords="offset points")
    cols = np.nonzero((state != -2).any(axis=0))[0]
    xs = [p["x_m"] for p in result["placements"]] + ([x0 + cols[0] * cell, x0 + (cols[-1] + 1) * cell] if cols.size else [])
    if xs:  # the stretch flown, not the whole seabed
        ax.set_xlim(max(extent[0], min(xs) - 1.5), min(extent[1], max(xs) + 1.5))
    rule = result["rule"]
    handles = [Patch(facecolor=DETECTED_COLOUR, edgecolor="black", label=f"detected (>= {rule['min_valid_soundings']} "
                     "valid soundings)"),
               Patch(facecolor=MISSED_COLOUR, edgecolor="black", label="missed (reached)"),
               Patch(facecolor=UNREACHED_COLOURS["not_reached"], edgecolor="black", label="no pulse reached it"),
               Patch(facecolor=UNREACHED_COLOURS["shadowed"], edgecolor="black", label="hidden by another object"),
               Patch(facecolor="#b8e0dc", edgecolor="grey", label="covered cell"),
               Patch(facecolor="#d9d9d9", edgecolor="grey", label="missed cell"),
               Patch(facecolor=COVERAGE_COLOURS["not_reached"], edgecolor="grey", label="not reached by the scan")]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, fontsize=8, frameon=False)
    rows = [f"{size} m: {c['detected']}/{c['reached']}" + _apart(c) for size, c in result["cubes"].items()]
    finish_plan_map(fig, ax, path_png, (title + "\n" if title else "") + "detected of those reached, per size: "
                    + ", ".join(rows),
                    x_label="x east [m]; label: cube size: its valid soundings")
