"""The Monte Carlo tables the package ships: every water preset with each instrument preset's geometry, built by
``python3 -m muls.validation.shipped_tables`` into ``muls/data/scattering`` (:mod:`muls.montecarlo.scattering_tables`).
"""

from __future__ import annotations

from ..montecarlo.scattering_tables import SHIPPED_DIR
from ..montecarlo.tables import TABLE_PACKETS, build_tables
from ..presets import WATER_PRESETS, coaxial, mul2023


def ship(out_dir=None, packets: int = TABLE_PACKETS) -> list:
    """Build the tables of every water preset with each instrument preset's geometry (the MUL's offset receiver and
    the coaxial one) into ``out_dir`` (default: the folder the package ships,
    :data:`muls.montecarlo.scattering_tables.SHIPPED_DIR`); returns the files written."""
    folder = SHIPPED_DIR if out_dir is None else out_dir
    written = []
    for geometry in {mul2023().geometry, coaxial().geometry}:
        for water in WATER_PRESETS.values():
            tables = build_tables(geometry, water, packets=packets)
            path = folder / f"{tables.key}.npz"
            tables.save(path)
            written.append(path)
            print(f"{water.name:14s} offset {geometry.offset_m:g} m: {path.name} ({tables.source})", flush=True)
    return written


if __name__ == "__main__":  # pragma: no cover
    ship()
