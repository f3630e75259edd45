"""Pictures and reports: the only place that imports matplotlib or pyvista (ruff's banned-API rule)."""
