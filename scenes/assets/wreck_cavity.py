"""Writes ``wreck_cavity.obj``: the hull of a small steel wreck as ONE closed mesh with step edges inside it.

The hull lies upright along y (bow at +y), its flat bottom at z = 0. Its topsides flare from the bottom's
half-width to the deck's, so the deck edge overhangs the seabed beside the bilge; an open hatch in the middle
of the deck leads into a hold whose floor lies ``HOLD_DEPTH_M`` below the deck. Every face's winding gives an
outward normal (out of the steel, into the water and into the open hold). Run from the repository's root:
``python scenes/assets/wreck_cavity.py``; ``tests/system/test_failure_scenes.py`` checks the shipped file is what this
writes. Dimensions: a small steel fishing vessel (named assumptions in docs/assumptions.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

LENGTH_M = 12.0
"""Hull length along y [m]."""
DECK_HALF_WIDTH_M = 2.25
"""Half the beam at the deck [m]."""
BOTTOM_HALF_WIDTH_M = 1.2
"""Half the width of the flat bottom [m]: the deck edge overhangs the seabed by 2.25 - 1.2 = 1.05 m."""
DECK_HEIGHT_M = 2.2
"""Deck above the bottom [m]."""
HATCH_HALF_SIZE_M = 0.6
"""Half the side of the square hatch, centred on the deck [m]."""
HOLD_DEPTH_M = 1.3
"""Hold floor below the deck [m]."""
OBJ_PATH = Path(__file__).with_suffix(".obj")


def wreck_mesh() -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) [m] and faces (m, 3) of the closed hull, outward winding."""
    w, b, h, a, half = DECK_HALF_WIDTH_M, BOTTOM_HALF_WIDTH_M, DECK_HEIGHT_M, HATCH_HALF_SIZE_M, 0.5 * LENGTH_M
    floor = h - HOLD_DEPTH_M
    xs_deck, ys = (-w, -a, a, w), (-half, -a, a, half)
    verts: list[tuple[float, float, float]] = []
    index: dict[tuple[float, float, float], int] = {}

    def v(x, y, z):
        key = (float(x), float(y), float(z))
        if key not in index:
            index[key] = len(verts)
            verts.append(key)
        return index[key]

    faces: list[tuple[int, int, int]] = []

    def quad(p0, p1, p2, p3):
        """p0..p3 counter-clockwise seen from outside."""
        faces.extend([(p0, p1, p2), (p0, p2, p3)])

    # Deck: a 3 x 3 grid of rectangles without the middle one (the hatch), normal +z.
    for i in range(3):
        for j in range(3):
            if (i, j) != (1, 1):
                x0, x1, y0, y1 = xs_deck[i], xs_deck[i + 1], ys[j], ys[j + 1]
                quad(v(x0, y0, h), v(x1, y0, h), v(x1, y1, h), v(x0, y1, h))
    # Hold: four walls facing into the hatch and the floor facing up.
    quad(v(-a, -a, h), v(-a, -a, floor), v(-a, a, floor), v(-a, a, h))  # normal +x
    quad(v(a, a, h), v(a, a, floor), v(a, -a, floor), v(a, -a, h))  # normal -x
    quad(v(a, -a, h), v(a, -a, floor), v(-a, -a, floor), v(-a, -a, h))  # normal +y
    quad(v(-a, a, h), v(-a, a, floor), v(a, a, floor), v(a, a, h))  # normal -y
    quad(v(-a, -a, floor), v(a, -a, floor), v(a, a, floor), v(-a, a, floor))
    # Flared topsides and the bottom, split at the hatch's y so that they share the deck's vertices.
    for j in range(3):
        y0, y1 = ys[j], ys[j + 1]
        quad(v(b, y0, 0), v(b, y1, 0), v(w, y1, h), v(w, y0, h))  # starboard, normal +x and down
        quad(v(-b, y1, 0), v(-b, y0, 0), v(-w, y0, h), v(-w, y1, h))  # port
        quad(v(-b, y0, 0), v(-b, y1, 0), v(b, y1, 0), v(b, y0, 0))  # flat bottom, normal -z
    # Transom (-y) and bow (+y): the trapezoid fanned from its bottom corners.
    for y, sign in ((-half, 1), (half, -1)):
        ring = [v(-b, y, 0), v(b, y, 0), *(v(x, y, h) for x in reversed(xs_deck))]
        for k in range(1, len(ring) - 1):
            tri = (ring[0], ring[k], ring[k + 1])
            faces.append(tri if sign > 0 else tri[::-1])
    return np.array(verts), np.array(faces, np.int64)


def write_obj(path: Path = OBJ_PATH) -> None:
    """The mesh as a Wavefront OBJ, 6 decimals."""
    verts, faces = wreck_mesh()
    lines = ["# scenes/assets/wreck_cavity.py: a wreck's hull, flared topsides, a hatch into its hold"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"f {i + 1} {j + 1} {k + 1}" for i, j, k in faces]
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    write_obj()
