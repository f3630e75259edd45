"""Byte-identity check of a tree's passes: SHA-256 of the points, dropouts and waveforms of 20 short passes.

Five shipped scenes x the four fidelity levels, each pass ``pulses`` pulses long with a fixed seed and 64 sampled
waveform records. Each pass runs in a child process with ``PYTHONPATH`` set to the tree, through the tree's own
``scanner-sim run``, so an older checkout (``git worktree add /tmp/before COMMIT``) is hashed by its own code. The
hash covers every point dimension of ``points.las`` or ``points.laz`` (not its header, which holds the creation date and the
software version), every array of ``dropouts.npz`` and of ``waveforms.npz``, by name, in sorted order.

    python -m scanner_sim.perf.pass_hashes /tmp/before .          # compare two trees, exit 1 on any difference
    python -m scanner_sim.perf.pass_hashes . --json hashes.json   # one tree's hashes
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

SCENES = ("cable_survey", "mine_field", "seabed_lawnmower", "real_site", "pond_panel")
LEVELS = ("fast", "balanced", "auto", "reference")


def _hash_npz(path: Path, digest) -> None:
    import numpy as np

    with np.load(path, allow_pickle=False) as arrays:
        for name in sorted(arrays.files):
            digest.update(name.encode())
            digest.update(np.ascontiguousarray(arrays[name]).tobytes())


def _hash_las(path: Path, digest) -> None:
    import laspy
    import numpy as np

    points = laspy.read(path).points
    for name in sorted(points.point_format.dimension_names):
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(points[name]).tobytes())


def pass_hashes(run_dir: Path) -> dict[str, str]:
    """SHA-256 per product of one run folder: ``{"points": hex, "dropouts": hex, "waveforms": hex}``."""
    out = {}
    for product, names, reader in (("points", ("points.las", "points.laz"), _hash_las),
                                   ("dropouts", ("dropouts.npz",), _hash_npz),
                                   ("waveforms", ("waveforms.npz",), _hash_npz)):
        for path in (run_dir / name for name in names if (run_dir / name).exists()):
            digest = hashlib.sha256()
            reader(path, digest)
            out[product] = digest.hexdigest()
    return out


def tree_hashes(tree: Path, pulses: int = 3000, seed: int = 7) -> dict[str, dict[str, str]]:
    """Hashes of the 20 passes run by the code in ``tree``: ``{"scene/level": pass_hashes}``."""
    tree = tree.resolve()
    env = dict(os.environ, PYTHONPATH=str(tree))
    result = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in SCENES:
            for level in LEVELS:
                out = Path(tmp) / f"{scene}-{level}"
                cmd = [sys.executable, "-c", "import sys; from scanner_sim.cli import main; sys.exit(main())",
                       "run", str(tree / "scenes" / f"{scene}.yaml"), "--fidelity", level, "--seed", str(seed),
                       "--max-pulses", str(pulses), "--waveforms", "64", "--no-render", "--quiet", "--out", str(out)]
                subprocess.run(cmd, cwd=tmp, env=env, check=True, stdout=subprocess.DEVNULL)
                result[f"{scene}/{level}"] = pass_hashes(out)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m scanner_sim.perf.pass_hashes", description=__doc__.split("\n")[0])
    parser.add_argument("trees", nargs="+", type=Path, help="one tree to hash, or two to compare")
    parser.add_argument("--pulses", type=int, default=3000)
    parser.add_argument("--json", type=Path, help="write the hashes of every tree here")
    args = parser.parse_args(argv)
    hashes = {str(tree): tree_hashes(tree, args.pulses) for tree in args.trees}
    if args.json:
        args.json.write_text(json.dumps(hashes, indent=1))
    first = next(iter(hashes.values()))
    differ = 0
    for key, products in first.items():
        cells = []
        for product, digest in products.items():
            same = all(h[key].get(product) == digest for h in hashes.values())
            differ += not same
            cells.append(f"{product} {digest[:12]}{'' if same else ' DIFFERS'}")
        print(f"{key:28s} " + "  ".join(cells))
    if len(hashes) > 1:
        print(f"{differ} of {sum(len(p) for p in first.values())} products differ")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
