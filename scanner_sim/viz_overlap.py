"""Overlap plot (ray-cast vs MULS Eq. 11). Kept apart from viz.py while that file has another owner; to be
folded into viz.py (the only module that may plot, STYLE.md rule 11)."""

from __future__ import annotations

from pathlib import Path


def plot_overlap(distance_m, raycast, analytic, path, subrays: int, dense_distance_m=None,
                 dense_analytic=None) -> Path:
    """Write a PNG of ray-cast overlap points over the Eq. 11 curve; returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    if dense_distance_m is not None:
        ax.plot(dense_distance_m, dense_analytic, "-", color="0.3", label="MULS Eq. 11")
    else:
        ax.plot(distance_m, analytic, "-", color="0.3", label="MULS Eq. 11")
    ax.plot(distance_m, raycast, "o", color="tab:red", label=f"ray-cast, {subrays} sub-rays")
    ax.set_xlabel("distance to a perpendicular plate [m]")
    ax.set_ylabel("overlap O(z)")
    ax.set_ylim(-0.03, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title("Beam / receiver-FOV overlap, mul2023 geometry")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
