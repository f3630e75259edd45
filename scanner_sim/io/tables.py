"""The small tables of a pass: trajectory.csv, waveforms.npz, coverage_grid.npz, and plain text files.

Every writer is atomic (:mod:`muls.infra.atomic`); formats in ``docs/outputs.md``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from muls.infra.atomic import PathLike, atomic_open
from scanner_sim.metrics.coverage import GAP_CAUSES

__all__ = [
    "read_coverage_grid_npz",
    "read_trajectory_csv",
    "read_waveforms_npz",
    "write_coverage_grid_npz",
    "write_text",
    "write_trajectory_csv",
    "write_waveforms_npz",
]


_ATTITUDE_COLUMNS = {
    "rpy_deg": ("roll_deg", "pitch_deg", "yaw_deg"),
    "quaternion": ("qw", "qx", "qy", "qz"),
}


def _check_2d(name: str, arr, n: int, width: int, dtype=np.float64) -> np.ndarray:
    a = np.asarray(arr, dtype=dtype)
    if a.shape != (n, width):
        raise ValueError(f"{name}: shape {a.shape} is not allowed; expected ({n}, {width})")
    return a


def write_trajectory_csv(
    path: PathLike,
    time_s,
    position_m,
    attitude,
    *,
    attitude_format: str = "rpy_deg",
    estimated_position_m=None,
    estimated_attitude=None,
) -> None:
    """Write platform poses as CSV with one header line, atomically.

    Parameters
    ----------
    time_s : (n,) float [s]
        Seconds from the pass start.
    position_m : (n, 3) float [m]
        True platform position in the world frame (x east, y north, z up).
    attitude : (n, 3) or (n, 4) float
        True attitude: ``attitude_format="rpy_deg"`` gives roll, pitch, yaw [deg] (platform frame
        x forward, y left, z up; yaw counter-clockwise from east); ``"quaternion"`` gives the
        platform-to-world rotation as (qw, qx, qy, qz), scalar first.
    estimated_position_m, estimated_attitude : same shapes, optional
        The navigation solution (true pose plus navigation noise), written as ``est_*`` columns.

    Columns: ``time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg`` (or ``qw,qx,qy,qz``), then
    ``est_x_m,...`` when given. Times are written with ``%.9f`` (ns), positions with ``%.6f``
    (micrometres), attitudes with ``%.9g``.
    """
    if attitude_format not in _ATTITUDE_COLUMNS:
        raise ValueError(
            f"attitude_format: {attitude_format!r} is not allowed; expected one of {sorted(_ATTITUDE_COLUMNS)}"
        )
    t = np.asarray(time_s, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"time_s: shape {t.shape} is not allowed; expected (n,)")
    n = t.shape[0]
    att_cols = _ATTITUDE_COLUMNS[attitude_format]
    cols = ["time_s", "x_m", "y_m", "z_m", *att_cols]
    blocks = [t[:, None], _check_2d("position_m", position_m, n, 3), _check_2d("attitude", attitude, n, len(att_cols))]
    fmts = ["%.9f", "%.6f", "%.6f", "%.6f"] + ["%.9g"] * len(att_cols)
    if (estimated_position_m is None) != (estimated_attitude is None):
        raise ValueError("estimated_position_m and estimated_attitude: give both or neither")
    if estimated_position_m is not None:
        cols += ["est_x_m", "est_y_m", "est_z_m", *(f"est_{c}" for c in att_cols)]
        blocks += [
            _check_2d("estimated_position_m", estimated_position_m, n, 3),
            _check_2d("estimated_attitude", estimated_attitude, n, len(att_cols)),
        ]
        fmts += ["%.6f"] * 3 + ["%.9g"] * len(att_cols)
    table = np.hstack(blocks)
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        np.savetxt(fh, table, delimiter=",", header=",".join(cols), comments="", fmt=fmts)


def read_trajectory_csv(path: PathLike) -> dict[str, np.ndarray]:
    """Read a trajectory CSV: column name -> (n,) float64 array."""
    with open(path, encoding="utf-8") as fh:
        names = fh.readline().strip().split(",")
        data = np.loadtxt(fh, delimiter=",", ndmin=2)
    if data.size == 0:
        data = np.zeros((0, len(names)))
    return {name: data[:, i] for i, name in enumerate(names)}


_WAVEFORM_RESERVED = {"pulse_index", "time_ns", "channel_names"}


def write_waveforms_npz(path: PathLike, pulse_index, time_ns, channels: Mapping[str, np.ndarray]) -> None:
    """Write digitised waveforms of selected pulses to a compressed ``.npz``, atomically.

    Parameters
    ----------
    pulse_index : (n_pulses,) int
        Pulse of each record.
    time_ns : (n_samples,) or (n_pulses, n_samples) float [ns]
        Sample times from emission (one grid for all, or one per pulse when the sampling phase is
        random per pulse).
    channels : dict name -> (n_pulses, n_samples) array
        One array per channel, e.g. ``{"ch0": ..., "ch1": ..., "ch2": ..., "ch3": ...}`` in ADC
        LSB (dtype kept as given). Names must be identifiers and not ``pulse_index``, ``time_ns``
        or ``channel_names``.

    Arrays stored: ``pulse_index``, ``time_ns``, ``channel_names`` (str, in the given order) and
    one array per channel under its name.
    """
    pi = np.asarray(pulse_index)
    if pi.ndim != 1 or (pi.size and pi.dtype.kind not in "iu"):
        raise ValueError(f"pulse_index: shape {pi.shape} dtype {pi.dtype} is not allowed; expected (n_pulses,) integers")
    pi = pi.astype(np.int64)
    n = pi.shape[0]
    t = np.asarray(time_ns, dtype=np.float64)
    if t.ndim not in (1, 2) or (t.ndim == 2 and t.shape[0] != n):
        raise ValueError(f"time_ns: shape {t.shape} is not allowed; expected (n_samples,) or ({n}, n_samples)")
    n_samples = t.shape[-1]
    if not isinstance(channels, Mapping) or not channels:
        raise ValueError("channels: expected a non-empty dict of name -> (n_pulses, n_samples) array")
    arrays = {}
    for name, data in channels.items():
        if not (isinstance(name, str) and name.isidentifier()) or name in _WAVEFORM_RESERVED:
            raise ValueError(
                f"channels: name {name!r} is not allowed; use an identifier other than {sorted(_WAVEFORM_RESERVED)}"
            )
        a = np.asarray(data)
        if a.shape != (n, n_samples):
            raise ValueError(f"channels[{name!r}]: shape {a.shape} is not allowed; expected ({n}, {n_samples})")
        arrays[name] = a
    with atomic_open(path) as fh:
        np.savez_compressed(
            fh, pulse_index=pi, time_ns=t, channel_names=np.array(list(arrays)), **arrays
        )


def read_waveforms_npz(path: PathLike) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Read ``(pulse_index, time_ns, channels)`` back from :func:`write_waveforms_npz` output."""
    with np.load(path, allow_pickle=False) as z:
        names = [str(s) for s in z["channel_names"]]
        return z["pulse_index"], z["time_ns"], {name: z[name] for name in names}


def write_coverage_grid_npz(path: PathLike, grid, state, reaching, valid, s44_order=None, planned=None) -> None:
    """Write a pass's plan-cell coverage to a compressed ``.npz``, atomically.

    ``grid`` is a :class:`scanner_sim.metrics.coverage.PlanGrid`; ``state`` (ny, nx) int16 (-2 not reached,
    -1 covered, else an index into ``gap_cause_names``); ``reaching`` and ``valid`` (ny * nx,) or
    (ny, nx) counts of reaching pulses and valid points per cell; ``s44_order`` the strictest S-44 order each cell
    complies with (index into ``s44_order_names``, -1 none) and ``planned`` (bool) the cells of the planned swath,
    each written when given. Row = y, column = x; cell (0, 0) has its lower-left corner at ``origin_m``.
    """
    from scanner_sim.metrics.s44 import ORDER_NAMES

    shape = tuple(grid.shape)
    arrays = {"state": np.asarray(state, np.int16), "reaching": np.asarray(reaching, np.int64),
              "valid": np.asarray(valid, np.int64)}
    if s44_order is not None:
        arrays |= {"s44_order": np.asarray(s44_order, np.int16), "s44_order_names": np.array(ORDER_NAMES)}
    if planned is not None:
        arrays["planned"] = np.asarray(planned, bool)
    for name, a in arrays.items():
        if name == "s44_order_names":
            continue
        if a.size != shape[0] * shape[1]:
            raise ValueError(f"{name}: {a.size} cells is not allowed; the grid has {shape[0]} x {shape[1]}")
        arrays[name] = a.reshape(shape)
    with atomic_open(path) as fh:
        np.savez_compressed(fh, origin_m=np.asarray(grid.origin_m, float), cell_m=np.float64(grid.cell_m),
                            gap_cause_names=np.array(GAP_CAUSES), **arrays)


def read_coverage_grid_npz(path: PathLike) -> dict[str, np.ndarray]:
    """The arrays of :func:`write_coverage_grid_npz` output, by name."""
    with np.load(path, allow_pickle=False) as z:
        return {name: z[name] for name in z.files}


def write_text(path: PathLike, text: str) -> None:
    """Write UTF-8 text (Markdown, HTML) atomically."""
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
