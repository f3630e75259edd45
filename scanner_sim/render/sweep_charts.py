"""Charts of a value against a swept axis, one curve per water, instrument or other axis: the coverage study's
covered fraction against altitude and a campaign's charts."""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence

import numpy as np

from scanner_sim.render.figure_png import figure_to_png

#: Curve colour per water preset in coverage charts (others take the matplotlib cycle).
WATER_COLOURS: dict[str, str] = {"clean_ocean": "#1f77b4", "coastal_ocean": "#2ca02c", "turbid_harbor": "#8c564b",
                                 "pool": "#17becf", "pond": "#bcbd22"}
_INSTRUMENT_STYLES = {"mul2023": ("-", "o"), "single_channel": ("--", "s"), "coaxial": (":", "^")}


def curve_layout(keys: Sequence[tuple], span: float) -> dict[tuple, tuple[float, float, float, int]]:
    """Per curve key, in drawing order: (x offset, line width, marker size, z-order). Every curve is drawn a little
    apart along x (2 % of ``span``, at least 0.02, between neighbours) and thinner, with smaller markers, than
    the one before, on top of it: curves of equal values (two instruments both at 100 %) all stay visible."""
    step = 0.02 * max(span, 1.0)
    n = len(keys)
    return {key: ((j - 0.5 * (n - 1)) * step, max(3.6 - 0.5 * j, 1.0), max(10.0 - 1.2 * j, 4.0), 2 + j)
            for j, key in enumerate(keys)}


def plot_coverage_vs_altitude(path_png, records: Sequence[Mapping], *, title: str | None = None) -> None:
    """Covered fraction [%] against altitude [m], one curve per water type and instrument.

    records: mappings with ``water``, ``instrument``, ``altitude_m`` and ``covered_fraction`` (0..1 or None).
    Colour tells the water, line style and marker the instrument. Where curves give equal coverage (clean and
    coastal at 100 %, or both instruments of one water), they stay visible (:func:`curve_layout`).
    """
    from matplotlib.figure import Figure

    curves: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for r in records:
        if r["covered_fraction"] is not None:
            curves.setdefault((r["water"], r["instrument"]), []).append((r["altitude_m"], 100.0 * r["covered_fraction"]))
    fig = Figure(figsize=(8.0, 5.0), dpi=110)
    ax = fig.add_subplot()
    cycle = iter(f"C{i}" for i in range(3, 100))
    colours: dict[str, str] = {}
    altitudes = [a for pts in curves.values() for a, _ in pts]
    layout = curve_layout(list(curves), max(altitudes) - min(altitudes) if altitudes else 0.0)
    for (water, instrument), pts in curves.items():
        colour = colours.setdefault(water, WATER_COLOURS.get(water) or next(cycle))
        line, marker = _INSTRUMENT_STYLES.get(instrument, ("-.", "D"))
        alt, frac = np.array(sorted(pts)).T
        dx, lw, ms, z = layout[(water, instrument)]
        ax.plot(alt + dx, frac, line, marker=marker, color=colour, lw=lw, ms=ms, zorder=z,
                label=f"{water}, {instrument}")
    ax.set_xlabel("altitude [m]")
    ax.set_ylabel("covered fraction of the reached area [%]")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    if curves:
        ax.legend(fontsize=8, loc="lower left")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    figure_to_png(fig, path_png)


def plot_sweep(path_png, records: Sequence[Mapping], x: str, y: str, *, lines: Sequence[str] = (),
               title: str | None = None, y_label: str | None = None) -> None:
    """A figure ``y`` against sweep axis ``x``, one curve per combination of the ``lines`` axes' values.

    records: mappings with keys ``x``, ``y`` and every name in ``lines`` (a campaign's passes); a record
    whose ``y`` is None is left out. Numeric ``x`` values are placed by value, others in first-seen order.
    Colour tells the value of ``lines[0]`` (a water preset's own colour when it is one), line style and
    marker the values of the other ``lines`` axes (an instrument's own style when it is one).
    """
    from matplotlib.figure import Figure

    def label(value):
        return f"{value:g}" if isinstance(value, float) else str(value)

    xs = [r[x] for r in records if r[y] is not None]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    places = {v: float(v) for v in xs} if numeric else {v: float(i) for i, v in enumerate(dict.fromkeys(map(str, xs)))}
    curves: dict[tuple, list[tuple[float, float]]] = {}
    for r in records:
        if r[y] is not None:
            key = tuple(r[name] for name in lines)
            curves.setdefault(key, []).append((places[r[x] if numeric else str(r[x])], float(r[y])))
    fig = Figure(figsize=(8.0, 5.0), dpi=110)
    ax = fig.add_subplot()
    colour_cycle, style_cycle = iter(f"C{i}" for i in range(100)), itertools.cycle(
        [("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ("-", "v"), ("--", "P")])
    colours: dict[tuple, str] = {}
    styles: dict[tuple, tuple[str, str]] = {}
    for key, pts in curves.items():
        if key[:1] not in colours:
            colours[key[:1]] = (WATER_COLOURS.get(str(key[0])) if key else None) or next(colour_cycle)
        if key[1:] not in styles:
            styles[key[1:]] = (_INSTRUMENT_STYLES.get(str(key[1])) if len(key) > 1 else None) or next(style_cycle)
        (line, marker), px_py = styles[key[1:]], np.array(sorted(pts)).T
        ax.plot(*px_py, line, marker=marker, color=colours[key[:1]],
                label=", ".join(f"{name}={label(v)}" for name, v in zip(lines, key)) or None)
    if not numeric:
        ax.set_xticks(list(places.values()), list(places))
    ax.set_xlabel(x)
    ax.set_ylabel(y_label or y)
    ax.grid(alpha=0.3)
    if lines and curves:
        ax.legend(fontsize=8, loc="best")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    figure_to_png(fig, path_png)
