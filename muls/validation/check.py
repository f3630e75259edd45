"""The acceptance check of ``muls multiscatter --json``: the worst relative statistical error over the bins
where each signal is within a factor WITHIN of its own peak, for the Monte Carlo's column, its target echo
and their sum.

    muls multiscatter --water pond --range-m 10 --json > pond.json
    python3 -m muls.validation.check pond.json
"""

from __future__ import annotations

import json
import sys

import numpy as np

#: Bins count where the signal is above its peak over this factor (the issue's "within 100 times").
WITHIN = 100.0
#: The JSON keys of each part: (power [W], relative error).
PARTS = {"column": ("mc_column_w", "mc_column_rel_err"), "target": ("mc_target_w", "mc_target_rel_err"),
         "total": ("mc_w", "mc_rel_err")}


def worst_errors(result: dict, within: float = WITHIN) -> dict:
    """Per part: the largest and median relative error over the bins within ``within`` of the part's peak.

    result: the JSON of ``muls multiscatter``. Returns {part: {"max_rel_err", "median_rel_err", "at_ns",
    "bins", "from_ns", "to_ns"}}.
    """
    t = np.asarray(result["time_ns"], float)
    out = {}
    for part, (key_w, key_err) in PARTS.items():
        w = np.asarray(result[key_w], float)
        err = np.asarray([np.nan if e is None else e for e in result[key_err]], float)
        inside = w > w.max() / within
        rel = err[inside]
        i = int(np.nanargmax(rel))
        out[part] = {"max_rel_err": float(rel[i]), "median_rel_err": float(np.nanmedian(rel)),
                     "at_ns": float(t[inside][i]), "bins": int(inside.sum()),
                     "from_ns": float(t[inside].min()), "to_ns": float(t[inside].max())}
    return out


def main(argv=None) -> int:
    """Print the check for a JSON file (``-``: standard input)."""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python3 -m muls.validation.check MULTISCATTER_JSON (or - for standard input)", file=sys.stderr)
        return 2
    with (sys.stdin if argv[0] == "-" else open(argv[0])) as f:
        result = json.load(f)
    print(f"{result['packets']:,} packets, {result['seconds']} s; bins within {WITHIN:g} times of each peak:")
    for part, r in worst_errors(result).items():
        print(f"{part:7s} {r['bins']:4d} bins ({r['from_ns']:.1f} to {r['to_ns']:.1f} ns): relative error max "
              f"{r['max_rel_err']:.2%} (at {r['at_ns']:.1f} ns), median {r['median_rel_err']:.2%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
