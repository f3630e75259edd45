"""Many passes at once: campaigns (sweeps of scene keys) and passes as Dask tasks, on a local cluster or a
scheduler, bit-identical to serial passes."""
