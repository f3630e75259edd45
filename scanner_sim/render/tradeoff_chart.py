"""The speed-against-accuracy chart of ``scanner-sim tradeoff``: pulses/s against each error metric."""

from __future__ import annotations

from collections.abc import Mapping

from scanner_sim.render.figure_png import figure_to_png

#: Panels of the speed-against-accuracy chart: (section, key, axis label).
TRADEOFF_PANELS = (
    ("vs_truth", "median_abs_range_error_m", "median |range error| vs truth [m]"),
    ("vs_truth", "p95_abs_range_error_m", "95th pct |range error| vs truth [m]"),
    ("vs_truth", "false_alarms_per_pulse", "false alarms per pulse"),
    ("vs_truth", "hidden_points_per_pulse", "points on hidden surfaces per pulse"),
    ("vs_reference", "missing_per_pulse", "returns missing vs reference per pulse"),
    ("vs_reference", "extra_per_pulse", "returns extra vs reference per pulse"),
    ("vs_reference", "p95_position_diff_m", "95th pct position diff vs reference [m]"),
    ("vs_reference", "coverage_diff", "coverage minus reference's"),
    ("vs_reference", "waveform_r2", "1 - waveform R² vs reference"),
)


def plot_tradeoff(path_png, result: Mapping) -> None:
    """Pulses/s (log axis) against each error metric of a ``scanner-sim tradeoff`` result, one panel per metric
    (:data:`TRADEOFF_PANELS`): the levels as large labelled markers joined in order, the single knobs of
    ``balanced`` as small grey labelled markers. A metric a run lacks (None) is left out of its panel."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig = Figure(figsize=(13.0, 11.0), dpi=100)
    axes = fig.subplots(3, 3).ravel()
    groups = (("levels", dict(color="C0", ms=9, marker="o", ls="-"), 9),
              ("knobs", dict(color="0.45", ms=5, marker="s", ls="none"), 7))
    for ax, (section, key, label) in zip(axes, TRADEOFF_PANELS):
        for group, style, size in groups:
            names, xs, ys = [], [], []
            for name, entry in sorted(result[group].items(), key=lambda item: item[1]["pulses_per_s"]):
                value = entry[section][key]
                if value is None:
                    continue
                names.append(name)
                xs.append(entry["pulses_per_s"])
                ys.append(1.0 - value if key == "waveform_r2" else value)
            ax.plot(xs, ys, **style)
            for name, x, y in zip(names, xs, ys):
                ax.annotate(name, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=size,
                            color=style["color"])
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 3.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1000:g}k" if v >= 1000 else f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        lo, hi = ax.get_xlim()
        ax.set_xlim(lo, hi * 1.8)  # room for the labels of the fastest runs
        ax.set_xlabel("pulses/s")
        ax.set_ylabel(label, fontsize=9)
        ax.grid(alpha=0.3, which="both")
    spread = " spread over the pass" if result.get("stretches") else ""
    fig.suptitle(f"speed against accuracy: {result['scene']}, {result['pulses']:,} pulses per run{spread}, "
                 f"reference = {result['reference']}", fontsize=11)
    fig.tight_layout()
    figure_to_png(fig, path_png)
