"""Pictures and reports: the only place that imports matplotlib or pyvista (ruff's banned-API rule).

Its modules import them inside the functions, so ``import scanner_sim`` stays light and works without a display;
every picture is written atomically (:func:`muls.infra.atomic.atomic_path`)."""
