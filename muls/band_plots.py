"""Pictures of bands over a family of phase functions (``muls sensitivity``): each member's curve against range, the
default drawn thick (matplotlib through :mod:`muls.plots`' helpers)."""

from __future__ import annotations

from .plots import _pyplot, _save

#: Panels of the sensitivity picture: quantity key, axis label, log scale.
SENSITIVITY_PANELS = (("echo_energy_j", "echo energy [J]", True), ("echo_peak_w", "echo peak [W]", True),
                      ("echo_delay_ns", "echo peak delay [ns]", False), ("column_w", "column at 2R/c_w [W]", True))


def plot_sensitivity(result: dict, path):
    """Four panels against range [m]: the echo's energy, peak and peak delay, the column's power; one line per phase
    function of the family (the default black and thick), the band shaded."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    r = [row["range_m"] for row in result["ranges"]]
    cmap = plt.get_cmap("tab10")
    for ax, (key, label, log) in zip(axes.ravel(), SENSITIVITY_PANELS):
        lo = [row[key]["min"] for row in result["ranges"]]
        hi = [row[key]["max"] for row in result["ranges"]]
        ax.fill_between(r, lo, hi, color="0.85", label="band (min-max)")
        for i, (name, values) in enumerate(result["members"].items()):
            default = i == 0
            ax.plot(r, values[key], color="k" if default else cmap(i % 10), lw=2.2 if default else 1.0,
                    ls="-" if default else ("--" if "FF" in name else ":"), label=name)
        ax.set_ylabel(label)
        if log:
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("plate range [m]")
    axes[0, 0].legend(fontsize=7, ncol=2)
    w = result["water"]
    fig.suptitle(f"{w['name']} (c {w['c_per_m']:g}, a {w['a_per_m']:g} per m): echo and column over "
                 f"{len(result['members'])} phase functions, plate {result['settings']['reflectance']:g}")
    return _save(fig, path, top=0.95)
