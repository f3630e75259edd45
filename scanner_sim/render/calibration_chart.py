"""The uncertainty's calibration chart: the coverage each THU/TVU level predicts against the share of points whose
true error it covers (``scanner-sim uncertainty --chart``)."""

from __future__ import annotations

from collections.abc import Mapping

from scanner_sim.render.figure_png import figure_to_png


def plot_calibration(path_png, calibration: Mapping, *, title: str) -> None:
    """calibration PNG from a pass's ``uncertainty.calibration`` (summary.json): for each predicted level q, the
    observed share of points within their vertical (TVU-like) and horizontal (THU-like) q bound, over the diagonal
    a calibrated model follows; the 95 % level (TVU and THU themselves) marked."""
    from matplotlib.figure import Figure

    chart = calibration["chart"]
    levels = chart["levels"]
    fig = Figure(figsize=(6.4, 5.6), dpi=110)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="calibrated (observed = predicted)")
    for key, colour, name in (("vertical", "tab:blue", "vertical |error| <= q bound of TVU's model"),
                              ("horizontal", "tab:orange", "horizontal error <= q radius of THU's model")):
        observed = [v if v is not None else float("nan") for v in chart[key]]
        ax.plot(levels, observed, marker="o", color=colour, label=name)
    ax.axvline(0.95, color="0.3", lw=0.8)
    ax.axhspan(0.90, 0.99, xmin=0.9, xmax=1.0, color="tab:green", alpha=0.15, label="0.90-0.99 at q = 0.95")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("predicted coverage q")
    ax.set_ylabel("observed share of points within the bound")
    ax.set_title(f"{title}\nTVU holds {_pct(calibration['vertical_within_tvu'])}, THU "
                 f"{_pct(calibration['horizontal_within_thu'])} of {calibration['points']:,} points", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    figure_to_png(fig, path_png)


def _pct(share) -> str:
    return "-" if share is None else f"{100 * share:.1f} %"
