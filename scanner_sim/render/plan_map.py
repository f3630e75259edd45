"""What every plan map shares: the coverage palette and the frame (x east, y north, equal scale, title) they are
finished and written in. :mod:`scanner_sim.render.coverage_map`, :mod:`scanner_sim.render.s44_map` and
:mod:`scanner_sim.render.features` draw on it."""

from __future__ import annotations

from scanner_sim.render.figure_png import figure_to_png

#: Colours of the coverage map: not reached, covered, then one per gap cause (scanner_sim.metrics.coverage.GAP_CAUSES).
COVERAGE_COLOURS: dict[str, str] = {
    "not_reached": "#f0f0f0",
    "covered": "#2a9d8f",
    "no_hit": "#9e9e9e",
    "blind_zone": "#7b2cbf",
    "below_threshold": "#d62828",
    "saturated": "#f4d35e",
    "masked_by_backscatter": "#f77f00",
    "outside_gate": "#277da1",
    "out_of_tolerance": "#e56b9f",
    "other_surface": "#495057",
}
#: Plan cells with no seabed (a raster's nodata, where a mesh seabed does not reach) on a coverage map.
NO_SEABED_COLOUR = "#1d3557"


def finish_plan_map(fig, ax, path_png, title: str | None, x_label: str = "x east [m]") -> None:
    """A plan map's axes (x east, y north, equal scale, the ticks in plain map coordinates), its title, written to
    ``path_png``."""
    ax.set_xlabel(x_label)
    ax.set_ylabel("y north [m]")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(map_coordinate_formatter())
    ax.set_aspect("equal")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    figure_to_png(fig, path_png)


def map_coordinate_formatter():
    """A matplotlib ``ScalarFormatter`` that ticks in whole map coordinates as a person reads them off a chart
    (4494780, not 780 under a ``+4.494e6`` offset): no offset, no scientific notation."""
    from matplotlib.ticker import ScalarFormatter

    formatter = ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    return formatter
