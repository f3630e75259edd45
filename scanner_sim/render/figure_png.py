"""A matplotlib figure written to a PNG, atomically (:func:`muls.infra.atomic.atomic_path`), nothing cut off."""

from __future__ import annotations

from muls.infra.atomic import atomic_path


def figure_to_png(fig, path_png) -> None:
    """Write ``fig`` at its own dpi to ``path_png``, the box fitted to every label."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with atomic_path(path_png) as tmp:
        with open(tmp, "wb") as fh:
            fig.savefig(fh, format="png", dpi=fig.dpi, bbox_inches="tight", pad_inches=0.15)  # no label cut off
