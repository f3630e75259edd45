"""s44_map.png: the strictest IHO S-44 order each plan cell complies with, the planned swath outlined, and each
order's compliant share of the surveyed area in the legend (:mod:`scanner_sim.metrics.s44`)."""

from __future__ import annotations

import numpy as np

from scanner_sim.render.plan_map import COVERAGE_COLOURS, finish_plan_map

#: Colour per order, strictest first (dark green to yellow-green: the loosest stays apart from the grey of "not
#: reached"), then "complies with none".
ORDER_COLOURS = ("#00441b", "#238b45", "#66bd63", "#a6d96a", "#e6f598")
NONE_COLOUR = "#fdae6b"


def plot_order_map(path_png, order, state, planned, extent_m, order_names, figures: dict, *,
                   title: str | None = None) -> None:
    """Plan map to a PNG. order (ny, nx) int: index into ``order_names`` of the strictest order a cell complies
    with, -1 none; state (ny, nx): coverage states (-2 not reached); planned (ny, nx) bool or None: the planned
    swath; extent_m (x_min, x_max, y_min, y_max) [m]; figures: the pass's coverage figures (``orders``: per order its
    ``cell_m``, ``min_soundings`` and ``compliant_fraction``)."""
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    order, state = np.asarray(order), np.asarray(state)
    codes = np.where(state == -2, 0, np.where(order < 0, 1, order.astype(np.int64) + 2))
    colours = [COVERAGE_COLOURS["not_reached"], NONE_COLOUR, *ORDER_COLOURS[: len(order_names)]]
    x0, x1, y0, y1 = (float(v) for v in extent_m)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig = Figure(figsize=(10.0, float(np.clip(7.0 * aspect + 2.0, 3.5, 12.0))), dpi=110)
    ax = fig.add_subplot()
    ax.imshow(codes, origin="lower", extent=(x0, x1, y0, y1), cmap=ListedColormap(colours), vmin=-0.5,
              vmax=len(colours) - 0.5, interpolation="nearest")
    if planned is not None and np.asarray(planned).any():
        ax.contour(np.asarray(planned, float), levels=[0.5], origin="lower", extent=(x0, x1, y0, y1),
                   colors="black", linewidths=0.8, linestyles="--")
    area = "planned swath" if figures.get("orders_area") == "planned_swath" else "reached area"
    handles = [Patch(facecolor=ORDER_COLOURS[k], edgecolor="grey",
                     label=f"{name} ({_cells(figures['orders'][name])}; complies on "
                           f"{_pct(figures['orders'][name]['compliant_fraction'])} of the {area})")
               for k, name in enumerate(order_names)]
    handles += [Patch(facecolor=NONE_COLOUR, edgecolor="grey", label="reached, complies with no order"),
                Patch(facecolor=COVERAGE_COLOURS["not_reached"], edgecolor="grey", label="not reached by the scan")]
    if planned is not None:
        handles.append(Patch(facecolor="none", edgecolor="black", linestyle="--", label="planned swath"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, fontsize=8, frameon=False,
              title="strictest S-44 order the cell complies with")
    finish_plan_map(fig, ax, path_png, title)


def _cells(order: dict) -> str:
    """The grid an order was judged on, e.g. "0.5 m cells, >= 5 soundings"."""
    count = f", ≥ {order['min_soundings']} soundings" if order["min_soundings"] > 1 else ", no count rule"
    return f"{order['cell_m']:g} m cells{count}"


def _pct(fraction) -> str:
    return "–" if fraction is None else f"{100 * fraction:.1f} %"
