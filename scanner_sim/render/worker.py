"""A pass's pictures drawn in a child process beside it: :class:`PictureWorker`.

A warm ``scanner-sim run`` of cable_survey spent about 3 s of its wall time after the pass on its three pictures, a
second of it importing pyvista, VTK and matplotlib. The worker is started before the pass's set-up, whose Python
runs on one core and leaves the other free: the child imports the drawing libraries and opens VTK's off-screen
render window there; while the pass runs it builds render.png's plotter and truth mesh
(:func:`~scanner_sim.render.point_cloud.prepare_point_cloud`), and the pictures are drawn in it at the pass's end while
the parent writes the other files.
The child is spawned (not forked: the parent holds OpenMP and Embree threads), so it imports only what drawing
needs. A picture's drawing function and its arguments are what the parent would have called: the PNGs are the same.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import Future, ProcessPoolExecutor

from muls.infra.runtime import end_of_command


class PictureWorker:
    """One child process that draws pictures in the order given; :meth:`finish` waits for them and raises the first
    error a drawing raised. A context manager: leaving it early (an error, Ctrl-C) cancels what has not started."""

    def __init__(self, three_d: bool = True):
        """``three_d``: also load pyvista and open its off-screen render window while the parent sets up."""
        self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        self._pending: list[Future] = [self._pool.submit(warm_up, three_d)]

    def draw(self, function, *args, **kwargs) -> None:
        """Call ``function(*args, **kwargs)`` (a module-level function: it is pickled by name) in the child."""
        self._pending.append(self._pool.submit(function, *args, **kwargs))

    def finish(self) -> None:
        """Wait for every drawing; raise the first error one raised (the child's traceback chained to it)."""
        self._pending.append(self._pool.submit(end_of_command))  # the child's exit, then, need not collect
        try:
            for future in self._pending:
                future.result()
        finally:
            self.close()

    def close(self) -> None:
        """Stop the child; drawings not started are cancelled, the one under way is waited for."""
        self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> PictureWorker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def warm_up(three_d: bool) -> None:
    """Import matplotlib's figure and PNG writer and, with ``three_d``, pyvista, and render one empty off-screen
    frame (VTK's EGL window and its shaders set up): the work every picture would otherwise start with."""
    from matplotlib.backends import backend_agg  # noqa: F401  (the plan maps' canvas)
    from matplotlib.figure import Figure  # noqa: F401

    if three_d:
        from scanner_sim.render.point_cloud import _prefer_headless_vtk

        _prefer_headless_vtk()
        import pyvista as pv

        plotter = pv.Plotter(off_screen=True, window_size=[16, 16])
        try:
            plotter.add_mesh(pv.PolyData([[0.0, 0.0, 0.0]]), point_size=1.0)
            plotter.screenshot(return_img=True)
        finally:
            plotter.close()
