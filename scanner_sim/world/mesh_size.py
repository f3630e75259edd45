"""A mesh file's triangle count read from its header or counted in its text, before any loading: a file too large
for the machine is refused at once instead of loading for minutes into an out-of-memory end."""

from __future__ import annotations

from pathlib import Path

from scanner_sim.world.ply_header import ply_element_counts

#: [bytes] Peak memory a triangle takes while trimesh loads and processes a mesh: 951 B measured on a binary STL of
#: 300,000 triangles with no shared vertex (its worst case), rounded up.
MESH_BYTES_PER_TRIANGLE = 1_000
#: Bytes of an OBJ file scanned at a time when counting its face lines.
_CHUNK_BYTES = 1 << 24


def declared_triangles(path: str | Path) -> int | None:
    """The triangles a mesh file holds, without loading it: a binary STL's header count (when the file's size is the
    one it implies), a PLY header's face count, an OBJ's face lines (each a triangle at least); None for other
    formats."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".stl":
        with open(path, "rb") as fh:
            head = fh.read(84)
        if len(head) == 84:
            count = int.from_bytes(head[80:84], "little")
            if path.stat().st_size == 84 + 50 * count:
                return count
        return None
    if suffix == ".ply":
        return (ply_element_counts(path) or {}).get("face")
    if suffix == ".obj":
        faces, previous = 0, b"\n"
        with open(path, "rb") as fh:
            while chunk := fh.read(_CHUNK_BYTES):
                text = previous + chunk
                faces += text.count(b"\nf ") + text.count(b"\nf\t")
                previous = chunk[-1:]
        return faces
    return None
