"""Pictures of the studies' results (the only muls module that plots; matplotlib imported inside, Agg).

Each function takes the dict a :mod:`muls.studies` function returned and a PNG path, and returns the path.
"""

from __future__ import annotations

GROUP_STYLE = {
    "single": ("single channel", "k", "-"),
    "near": ("near field (CH1/CH2)", "tab:blue", "-"),
    "far": ("far field (CH3, gated)", "tab:red", "-"),
    "total": ("MUL total (chosen returns)", "tab:green", "--"),
}
CHANNEL_COLOURS = {"ch0": "0.3", "ch1": "tab:blue", "ch2": "tab:orange", "ch3": "tab:red", "chosen": "k"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path, top: float = 1.0):
    fig.tight_layout(rect=(0.0, 0.0, 1.0, top))
    fig.savefig(path, dpi=120)
    _pyplot().close(fig)
    return path


def plot_waveform(result: dict, path):
    """One panel per channel (CH0-CH3): noisy codes [LSB] drawn over the dashed noise-free curve vs time
    [ns], the full-scale code and the far channel's gate labelled, the time axis cut to where the echoes are."""
    plt = _pyplot()
    names = list(result["channels"])
    s = result["settings"]
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.1 * len(names)), sharex=True)
    t = result["time_ns"]
    echo_ns = 2e9 * s["range_m"] / s["speed_m_s"]
    for ax, name in zip(axes, names):
        colour = CHANNEL_COLOURS.get(name, "tab:purple")
        ax.plot(t, result["noise_free"][name], color="0.35", lw=1.0, ls="--", label="noise-free", zorder=1)
        ax.plot(t, result["channels"][name], color=colour, lw=0.9, label=f"{name} (noisy)", zorder=2)
        ax.axhline(s["max_code"], color="0.5", lw=0.7, ls=":", label=f"full scale ({s['max_code']} LSB)")
        for r in result["returns"]:  # the chosen return's range, back to time of flight
            if r["channel"] == name:
                ax.axvline(2e9 * r["range_m"] / s["speed_m_s"], color="tab:green", lw=0.8, label="chosen return")
        if name == "ch3":
            d, w = s["gate_delay_ns"], s["gate_width_ns"]
            ax.axvspan(d, d + w, color="tab:red", alpha=0.08, lw=0, label=f"gate {d:g}-{d + w:g} ns")
        ax.set_ylabel("LSB")
        ax.set_ylim(top=1.12 * s["max_code"])
        ax.legend(loc="upper right", fontsize=7)
    # The echoes and the column lie in the first tens of ns; show them, and the gate's opening.
    right = max(echo_ns + 80.0, s["gate_delay_ns"] + 40.0 if "ch3" in names else 0.0)
    axes[-1].set_xlim(t[0], min(t[-1], right))
    axes[-1].set_xlabel("time after emission [ns]")
    axes[0].set_title(f"{s['water']}: panel at {s['range_m']:g} m, reflectance {s['reflectance']:g}, seed {s['seed']}")
    return _save(fig, path)


def plot_maxrange(result: dict, path):
    """Detection fraction vs range, one panel per water, one curve per channel group, 90 % line."""
    plt = _pyplot()
    waters = result["settings"]["waters"]
    level = result["settings"]["detection_fraction"]
    fig, axes = plt.subplots(len(waters), 1, figsize=(8, 2.6 * len(waters)), squeeze=False)
    keys = {"single": "single_channel_m", "near": "near_field_m", "far": "far_field_m", "total": "total_m"}
    for ax, w in zip(axes[:, 0], waters):
        c = result[w]["curves"]
        for g, (label, colour, ls) in GROUP_STYLE.items():
            edge = result[w][keys[g]]
            ax.plot(c["range_m"], c[g], color=colour, ls=ls, lw=1.2,
                    label=f"{label}: {edge:.1f} m" if edge is not None else f"{label}: -")
            if edge is not None:
                ax.axvline(edge, color=colour, lw=0.6, ls=":")
        ax.axhline(level, color="0.5", lw=0.6)
        total = result.get("band", {}).get("waters", {}).get(w, {}).get("figures", {}).get("total_m")
        if total and total["low"] is not None:  # the MUL's total range over the family of phase functions
            ax.axvspan(total["low"], total["high"], color="tab:green", alpha=0.12,
                       label=f"total over the phase functions: {total['low']:.1f}-{total['high']:.1f} m")
        ax.set_ylim(-0.03, 1.03)
        top = max([result[w][k] or 0.0 for k in keys.values()] + [total["high"] if total and total["high"] else 0.0])
        ax.set_xlim(0, max(5.0, 1.4 * top))
        ax.set_ylabel("detected fraction")
        ax.set_title(f"{w} (improvement {result[w]['improvement']})", fontsize=10)
        ax.legend(fontsize=7, loc="lower left")
    axes[-1, 0].set_xlabel("target range [m]")
    return _save(fig, path)


def plot_precision(result: dict, path):
    """Range precision (std) and mean deviation [m] vs range, per channel."""
    plt = _pyplot()
    keys = [k for k in result if k != "settings"]
    ranges = [float(k) for k in keys]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for ch in result[keys[0]]:
        colour = CHANNEL_COLOURS.get(ch, "tab:purple")
        for ax, field in ((a1, "precision_m"), (a2, "mean_deviation_m")):
            pts = [(r, result[k][ch][field]) for r, k in zip(ranges, keys) if result[k][ch][field] is not None]
            if pts:
                ax.plot(*zip(*pts), marker="o", color=colour, ls="--" if ch == "chosen" else "-", label=ch)
    s = result["settings"]
    a1.set_ylabel("range precision (std) [m]")
    a2.set_ylabel("mean deviation (measured - true) [m]")
    a2.axhline(0.0, color="0.5", lw=0.6)
    for ax in (a1, a2):
        ax.set_xlabel("target range [m]")
        ax.legend(fontsize=8)
    fig.suptitle(f"{s['water']}, {s['shots']} shots per range, CH3 gate {s['gate_delay_ns']:g}/{s['gate_width_ns']:g} ns")
    return _save(fig, path)


def plot_coaxial(results: dict, path):
    """Column power [W] vs time [ns], coaxial (solid) vs non-coaxial (dashed), one colour per water.

    results: {water name: coaxial_study(...) dict}.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    colours = ["tab:brown", "tab:green", "tab:blue", "tab:purple", "tab:orange"]
    for colour, (w, r) in zip(colours, results.items()):
        ax.semilogy(r["time_ns"], r["coaxial_w"], color=colour, lw=1.2, label=f"{w} coaxial")
        ax.semilogy(r["time_ns"], r["non_coaxial_w"], color=colour, lw=1.2, ls="--",
                    label=f"{w} non-coaxial (peak ratio {r['peak_ratio']:.1f})")
    peak = max(r["coaxial_peak_w"] for r in results.values())
    ax.set_ylim(peak * 1e-6, peak * 3)
    ax.set_xlabel("time after emission [ns]")
    ax.set_ylabel("water-column power [W]")
    ax.set_title("Water-column backscatter, both receivers non-gated (paper Fig. 13)")
    ax.legend(fontsize=7)
    return _save(fig, path)


def plot_multiscatter(result: dict, path):
    """Monte Carlo and MULS power [W] vs time [ns] on a log axis (column and target apart), and their ratio.

    result: the dict of :func:`muls.studies.multiscatter_study` (with its ``details``).
    """
    import numpy as np

    plt = _pyplot()
    d = result["details"]
    t = np.asarray(result["time_ns"])
    mc, muls = np.asarray(result["mc_w"]), np.asarray(result["muls_w"])
    err = np.asarray([np.nan if e is None else e for e in result["mc_rel_err"]])
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    ax.semilogy(t, mc, color="tab:red", lw=1.4, label="Monte Carlo, column + target")
    ax.fill_between(t, mc * (1 - 2 * np.nan_to_num(err)), mc * (1 + 2 * np.nan_to_num(err)), color="tab:red",
                    alpha=0.2, lw=0, label="Monte Carlo, 2 standard errors")
    ax.semilogy(t, d["mc_column_w"], color="tab:red", lw=0.8, ls="--", label="Monte Carlo, column")
    ax.semilogy(t, d["mc_column_first_w"], color="tab:orange", lw=0.8, ls=":",
                label="Monte Carlo, column, first scattering only")
    ax.semilogy(t, d["mc_target_w"], color="tab:red", lw=0.8, ls="-.", label="Monte Carlo, target")
    ax.semilogy(t, muls, color="k", lw=1.4, label=f"MULS ({d['attenuation_rules_per_m']['muls_model']}), column + target")
    ax.semilogy(t, d["muls_column_w"], color="k", lw=0.8, ls="--", label="MULS, column")
    ax.semilogy(t, d["muls_target_w"], color="k", lw=0.8, ls="-.", label="MULS, target")
    top = max(mc.max(), muls.max())
    floor = min(v for v in (np.max(d["mc_target_w"]), np.max(d["muls_target_w"]), top) if v > 0) * 1e-3
    ax.set_ylim(floor, top * 3)
    ax.set_ylabel("received optical power [W]")
    tg = result["target"]
    ratio, k_eff = tg["ratio"], result["effective_attenuation_per_m"]
    ax.set_title(f"{d['water']}, {d['geometry']}, plate at {d['range_m']:g} m: echo energy MC/MULS "
                 f"{'-' if ratio is None else f'{ratio:.3g}'}, k_eff {'-' if k_eff is None else f'{k_eff:.3f}'}/m "
                 f"({result['packets']:,} packets)", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where((muls > top * 1e-9) & (mc > 0), mc / muls, np.nan)
    ax2.semilogy(t, ratio, color="tab:purple", lw=1.0)
    ax2.axhline(1.0, color="0.5", lw=0.6)
    ax2.set_ylabel("MC / MULS")
    ax2.set_xlabel("time after emission [ns]")
    return _save(fig, path)


def plot_multiscatter_study(result: dict, path):
    """The study's chart: MC / MULS echo energy vs range per water for each attenuation rule, the effective
    attenuation vs range, and the column peak ratios (result: :func:`muls.studies.multiscatter_waters_study`).
    """
    import numpy as np

    plt = _pyplot()
    waters = result["settings"]["waters"]
    colours = dict(zip(waters, ["tab:brown", "tab:blue", "tab:cyan", "tab:green", "tab:purple"]))
    styles = {"k_lidar": "-", "c": ":", "kd": "--", "small_angle": "-."}
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.8))
    for w in waters:
        rows = result[w]["ranges"]
        r = np.array([q["range_m"] for q in rows])
        for rule, ls in styles.items():
            a1.semilogy(r, [q["ratio"][rule] for q in rows], color=colours[w], ls=ls, lw=1.2,
                        label=f"{w}, {rule}" if rule == "k_lidar" else None)
        a2.plot(r, [q["effective_attenuation_per_m"] for q in rows], color=colours[w], marker="o", ms=3, label=w)
        for rule, value in result[w]["attenuation_per_m"].items():  # the range-independent rules
            a2.axhline(value, color=colours[w], ls=styles[rule], lw=0.6, alpha=0.6)
    a1.axhline(1.0, color="0.4", lw=0.6)
    a1.set_xlabel("plate range [m]")
    a1.set_ylabel("echo energy, Monte Carlo / MULS")
    a1.set_title("target echo (solid k_lidar, dotted c, dashed kd, dash-dot small_angle)", fontsize=9)
    a1.set_ylim(1e-4, 1e3)
    a1.legend(fontsize=7)
    a2.set_xlabel("plate range [m]")
    a2.set_ylabel("effective two-way attenuation [1/m]")
    a2.set_yscale("log")
    a2.set_title("Monte Carlo k_eff (markers); MULS rules (lines)", fontsize=9)
    a2.legend(fontsize=7)
    x = np.arange(len(waters))
    for i, (rule, hatch) in enumerate((("k_lidar", ""), ("c", "//"), ("kd", ".."), ("small_angle", "xx"))):
        a3.bar(x + (i - 1.5) * 0.2, [result[w]["column"]["rules"][rule]["peak_ratio"] for w in waters], width=0.2,
               color=[colours[w] for w in waters], hatch=hatch, edgecolor="k", lw=0.4, label=rule)
    a3.set_yscale("log")
    a3.axhline(1.0, color="0.4", lw=0.6)
    a3.set_xticks(x, waters, rotation=20, fontsize=8)
    a3.set_ylabel("column peak, Monte Carlo / MULS")
    a3.set_title("water-column peak (bars: k_lidar, c //, kd dotted, small_angle xx)", fontsize=9)
    fig.suptitle(f"Where single scattering fails: {result['settings']['geometry']}, "
                 f"{result['settings']['packets']:,} packets per water", fontsize=10)
    return _save(fig, path)


def plot_experiment(result: dict, path):
    """One shot's record per distance (rows) and channel CH1-CH3 (columns), like the paper's Figures 7, 8 and
    10: the noisy codes [LSB] over the dashed noise-free curve vs time [ns], the full-scale code, CH3's gate,
    the true echo time and the peaks the ranging found; each row titled with the distance's statistics."""
    plt = _pyplot()
    s = result["settings"]
    waves = result["waveforms"]
    names = [n for n in waves[0]["channels"] if n != "ch0"]
    fig, axes = plt.subplots(len(waves), len(names), figsize=(4.2 * len(names), 1.9 * len(waves) + 0.6),
                             squeeze=False, sharex="row")
    for row, wave in zip(axes, waves):
        key = f"{wave['range_m']:g}"
        echo_ns = 2e9 * wave["range_m"] / s["speed_m_s"]
        t = wave["time_ns"]
        for ax, name in zip(row, names):
            colour = CHANNEL_COLOURS.get(name, "tab:purple")
            ax.plot(t, wave["noise_free"][name], color="0.35", lw=0.9, ls="--", zorder=1)
            ax.plot(t, wave["channels"][name], color=colour, lw=0.8, zorder=2)
            ax.axhline(s["max_code"], color="0.5", lw=0.6, ls=":")
            ax.axvline(echo_ns, color="k", lw=0.5, alpha=0.4)
            if name == "ch3":
                d, w = s["gate_delay_ns"], s["gate_width_ns"]
                ax.axvspan(d, d + w, color="tab:red", alpha=0.07, lw=0)
            for p in wave["peaks"]:
                if p["channel"] == name:
                    ax.plot(p["time_ns"], s["max_code"] * 1.04, marker="v", color="tab:green", ms=5)
            st = result["distances"][key][name]
            prec = "-" if st["precision_m"] is None else f"{100 * st['precision_m']:.1f} cm"
            ax.set_title(f"{key} m {name}: detected {st['detected_fraction']:.0%}, std {prec}"
                         + (f", clipped {st['clipped_fraction']:.0%}" if st["clipped_fraction"] else ""), fontsize=8)
            ax.set_ylim(-20, 1.12 * s["max_code"])
            ax.tick_params(labelsize=7)
        right = max(echo_ns + 60.0, (s["gate_delay_ns"] + 40.0) if "ch3" in names else 0.0)
        row[0].set_xlim(0.0, min(t[-1], right))
        row[0].set_ylabel("LSB", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time after emission [ns]", fontsize=8)
    fig.suptitle(f"{s['experiment']}: panel {s['reflectance']:g}, M1 {s['gain_pmt1']:.0f}, M2 {s['gain_pmt2']:.0f}, "
                 f"CH3 gate {s['gate_delay_ns']:g}/{s['gate_width_ns']:g} ns, {s['ranging']} ranging, "
                 f"{s['attenuation_model']} attenuation\n(solid: one shot; dashed: noise-free; v: the peaks the ranging "
                 "found; grey line: the echo's start; shaded: CH3's gate)", fontsize=9)
    return _save(fig, path, top=1.0 - 0.5 / (1.9 * len(waves) + 0.6))


def plot_mobley1993(result: dict, path):
    """Mobley et al. (1993) problems 1 and 2: one panel per problem and albedo, each value of Table 5 (Ed, Eou,
    Lu at three optical depths) as the Monte Carlo over the paper's mean, with 2-standard-error bars, beside the
    range of the paper's codes over the same mean (grey bars).

    result: the dict of :func:`muls.validation.mobley1993.mobley1993_benchmark`.
    """
    plt = _pyplot()
    colours = {"Ed": "tab:blue", "Eou": "tab:orange", "Lu": "tab:green"}
    cases = sorted({(r["problem"], r["albedo"]) for r in result["problems"]}, key=lambda c: (c[0], -c[1]))
    fig, axes = plt.subplots(1, len(cases), figsize=(3.4 * len(cases), 4.4), sharey=True)
    for ax, (problem, albedo) in zip(axes, cases):
        rows = [r for r in result["problems"] if (r["problem"], r["albedo"]) == (problem, albedo)]
        for x, r in enumerate(rows):
            m = r["paper_mean"]
            ax.vlines(x, r["paper_min"] / m, r["paper_max"] / m, color="0.75", lw=7,
                      label="paper: range of the codes" if x == 0 else None)
            first = r is next(q for q in rows if q["quantity"] == r["quantity"])
            ax.errorbar(x, r["value"] / m, yerr=2 * r["mc_sigma"] / m, fmt="o", ms=4, capsize=2, lw=1,
                        color=colours[r["quantity"]], label=f"{r['quantity']}, Monte Carlo +- 2 sigma" if first else None)
        ax.axhline(1.0, color="0.4", lw=0.6)
        ax.set_xticks(range(len(rows)), [f"{r['quantity']}\n{r['optical_depth']:g}" for r in rows], fontsize=7)
        ax.set_xlabel("quantity, optical depth tau")
        ax.set_title(f"problem {problem} ({'Rayleigh' if problem == 1 else 'Petzold'}), albedo {albedo:g}", fontsize=9)
    axes[0].set_ylabel("value / the paper's mean")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Mobley et al. (1993) Table 5 against the Monte Carlo's transport ({result['photons']:,} photons "
                 "per run at albedo 0.9, more at 0.2)", fontsize=10)
    return _save(fig, path, top=0.93)


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
