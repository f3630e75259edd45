"""A first-order recursive filter, y[n] = b0 x[n] + b1 x[n-1] + r y[n-1] with x[-1] = y[-1] = 0.

It is the one filter the package needs (running integrals of the column profile, AR(1) navigation noise), and
``scipy.signal.lfilter([b0, b1], [1, -r], x)`` computes the same numbers in the same order (direct form II
transposed); this kernel spares every process the second or more that importing ``scipy.signal`` takes.
"""

from __future__ import annotations

import numpy as np

from .runtime import kernel


@kernel(nogil=True)
def _filter_columns(x, r, b0, b1):
    n, m = x.shape
    y = np.empty((n, m))
    for j in range(m):
        state = 0.0  # lfilter's state: b1 x[n-1] + r y[n-1]
        for i in range(n):
            out = b0 * x[i, j] + state
            state = b1 * x[i, j] + r * out
            y[i, j] = out
    return y


def first_order_filter(x: np.ndarray, r: float, b0: float = 1.0, b1: float = 0.0) -> np.ndarray:
    """``x`` (n,) or (n, m) float filtered along axis 0 by y[n] = b0 x[n] + b1 x[n-1] + r y[n-1]; same shape."""
    x = np.asarray(x, np.float64)
    y = _filter_columns(np.ascontiguousarray(x.reshape(x.shape[0], -1)), float(r), float(b0), float(b1))
    return y.reshape(x.shape)
