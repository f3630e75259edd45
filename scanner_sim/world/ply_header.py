"""What a PLY file's header promises, read before trimesh loads the file: its element counts, so that a mesh
object whose file would not fit is refused first (:func:`scanner_sim.world.mesh_file.load_mesh_file`)."""

from __future__ import annotations

from os import PathLike

#: [bytes] How much of a file :func:`ply_element_counts` reads looking for the end of a PLY header.
MAX_PLY_HEADER_BYTES = 64 << 10


def ply_element_counts(path: str | PathLike) -> dict[str, int] | None:
    """The element counts a PLY file's header promises (``{"vertex": 4, "face": 2}``), or None when the file does
    not start with a PLY header (within :data:`MAX_PLY_HEADER_BYTES`). Reads the header only."""
    with open(path, "rb") as fh:
        head = fh.read(MAX_PLY_HEADER_BYTES)
    if not head.startswith(b"ply") or b"end_header" not in head:
        return None
    counts = {}
    for line in head[:head.index(b"end_header")].decode("ascii", "replace").splitlines():
        words = line.split()
        if len(words) == 3 and words[0] == "element" and words[2].isdigit():
            counts[words[1]] = int(words[2])
    return counts
