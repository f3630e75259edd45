"""The survey planner's chart: per water, each candidate plan's survey time against its compliance with the order,
the chosen plan marked (``scanner-sim plan``, docs/planning.md)."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping

from scanner_sim.render.figure_png import figure_to_png

#: Marker of each candidate's status.
STATUS_STYLE = {"chosen": dict(marker="*", s=260, color="#d7301f", zorder=5, edgecolor="black", linewidths=0.6),
                "rejected": dict(marker="o", s=36, zorder=3)}


def plot_plan_chart(path_png, plan: Mapping) -> None:
    """One panel per water of ``plan`` (plan.json's content): every candidate at (survey time [min], predicted
    compliant share [%]), coloured by altitude, the required share as a dashed line, the chosen plan as a red star
    with its confirmed share as a cross; a water without a plan says so in its panel."""
    from matplotlib.figure import Figure

    waters = plan["waters"]
    fig = Figure(figsize=(5.2 * len(waters), 4.4), dpi=100)
    axes = fig.subplots(1, len(waters), squeeze=False)[0]
    altitudes = sorted({c["altitude_m"] for w in waters for c in w["candidates"]})
    colours = {a: f"C{i}" for i, a in enumerate(altitudes)}
    need = 100 * plan["required_share"] * min(1.0, plan["order_figures"]["coverage_percent"] / 100)
    for ax, water in zip(axes, waters):
        for a in altitudes:
            cands = [c for c in water["candidates"] if c["altitude_m"] == a]
            if cands:
                ax.scatter([c["survey_time_s"] / 60 for c in cands], [100 * c["predicted_share"] for c in cands],
                           color=colours[a], label=f"{a:g} m altitude", **STATUS_STYLE["rejected"])
        chosen = water["chosen"]
        if chosen is not None:
            t = chosen["survey_time_s"] / 60
            ax.scatter([t], [100 * chosen["predicted_share"]], label="chosen (predicted)", **STATUS_STYLE["chosen"])
            ax.scatter([t], [100 * chosen["confirmed"]["compliant_share"]], marker="x", s=80, color="black", zorder=6,
                       label="chosen (confirmed)")
            ax.annotate(f"{chosen['spacing_m']:.2f} m lines, {chosen['speed_m_s']:g} m/s", (t, 100 * chosen["predicted_share"]),
                        textcoords="offset points", xytext=(8, -14), fontsize=8)
            title = f"{water['water']}: {t:.1f} min"
        else:
            title = f"{water['water']}: not achievable"
            # matplotlib's wrap=True wraps at the figure's edge, not the panel's: wrapped to the panel by hand
            cause = textwrap.fill(f"best order: {water['best_order'] or 'none'}; {water['limiting_cause']}", 42)
            ax.text(0.5, 0.5, cause, transform=ax.transAxes, ha="center", va="center", fontsize=8,
                    bbox=dict(facecolor="white", edgecolor="0.7"))
        ax.axhline(need, color="0.3", ls="--", lw=1, label=f"required {need:g} %")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("survey time [min]")
        ax.set_ylabel(f"predicted {plan['order']} compliance [% of area]")
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle(f"{plan['scene']}: IHO S-44 {plan['order']} order, survey time against compliance", fontsize=11)
    figure_to_png(fig, path_png)
