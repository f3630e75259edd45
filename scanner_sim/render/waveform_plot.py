"""A pulse's digitised records, one panel per channel, over their noise-free curves (the MULS paper's Figures 7
and 8)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scanner_sim.render.figure_png import figure_to_png


def plot_waveforms(
    path_png,
    time_ns,
    channels: Mapping[str, np.ndarray],
    noise_free: Mapping[str, np.ndarray] | None = None,
    title: str | None = None,
    *,
    adc_max_lsb: float | None = None,
) -> None:
    """Digitised records of one pulse, one panel per channel, over their noise-free curves.

    Like the MULS paper's Figures 7 and 8: amplitude [LSB] against time [ns] for CH0..CH3.

    Parameters
    ----------
    time_ns : (n_samples,) float [ns]
        Sample times from emission.
    channels : dict name -> (n_samples,) array [LSB]
        Noisy digitised records, drawn as steps; panels in the dict's order.
    noise_free : dict name -> (n_samples,) array [LSB], optional
        The same channels without noise (and without quantisation), drawn dashed.
    adc_max_lsb : float, optional
        Full-scale code (e.g. 1023 for 10 bits), drawn as a dotted saturation line.
    """
    t = np.asarray(time_ns, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"time_ns: shape {t.shape} is not allowed; expected (n_samples,)")
    if not isinstance(channels, Mapping) or not channels:
        raise ValueError("channels: expected a non-empty dict of name -> (n_samples,) array")
    for label, group in (("channels", channels), ("noise_free", noise_free or {})):
        for name, data in group.items():
            if np.shape(data) != t.shape:
                raise ValueError(f"{label}[{name!r}]: shape {np.shape(data)} is not allowed; expected {t.shape}")
    unknown = set(noise_free or {}) - set(channels)
    if unknown:
        raise ValueError(f"noise_free: channels {sorted(unknown)} are not in channels ({list(channels)})")

    from matplotlib.figure import Figure

    n = len(channels)
    fig = Figure(figsize=(9.0, 1.9 * n + 0.8), dpi=110, layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for ax, (name, data) in zip(axes, channels.items()):
        ax.plot(t, np.asarray(data, dtype=np.float64), drawstyle="steps-mid", lw=0.9, color="tab:blue",
                label="digitised")
        if noise_free is not None and name in noise_free:
            ax.plot(t, np.asarray(noise_free[name], dtype=np.float64), "--", lw=1.2, color="k", label="noise-free")
        if adc_max_lsb is not None:
            ax.axhline(adc_max_lsb, ls=":", color="tab:red", lw=1.0, label="full scale")
        ax.set_ylabel(f"{name} [LSB]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time from emission [ns]")
    if title:
        fig.suptitle(title)
    figure_to_png(fig, path_png)
