"""A batch's serial kernels on several cores: the batch cut into contiguous blocks, one thread each.

The physics kernels are serial (numba's parfor lowering of them cost most of a first run's compile time) and
release the GIL, so blocks of a large batch run side by side on Python threads. Each kernel writes block by block
into one output (or its blocks are concatenated in order), and every item (pulse, window, peak) depends on its
own inputs alone (noise is keyed by seed, pulse id, stream and sample), so the result is the same bytes whatever
the blocks. How many threads: numba's thread count of the calling thread (``numba.set_num_threads``), as for a
parallel kernel: all cores by default, and one in a thread that set it to one (a mission's pass runs each chunk
so, and its chunks side by side).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

#: Items a block holds at least: a thread costs about 0.1 ms, a window or a pulse some microseconds.
MIN_BLOCK = 512


def block_bounds(n: int) -> np.ndarray:
    """(k + 1,) int64 bounds of k near-equal contiguous blocks of ``n`` items: one per thread of numba's count for
    this thread, fewer where a block would hold under :data:`MIN_BLOCK` items (one block, [0, n], for a small
    batch)."""
    import numba  # here: the command lines' --help imports this module's callers but no kernel

    parts = max(1, min(numba.get_num_threads(), n // MIN_BLOCK))
    return np.linspace(0, n, parts + 1).astype(np.int64)


def in_blocks(run, n: int) -> list:
    """``[run(start, stop) for each block]`` of :func:`block_bounds`, the blocks on threads side by side when more
    than one; in block order."""
    bounds = block_bounds(n)
    if bounds.shape[0] == 2:
        return [run(0, n)]
    with ThreadPoolExecutor(max_workers=bounds.shape[0] - 1, thread_name_prefix="block") as pool:
        return list(pool.map(run, bounds[:-1].tolist(), bounds[1:].tolist()))
