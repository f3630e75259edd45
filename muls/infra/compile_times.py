"""Where a command's numba compilation goes: each kernel's own compile time, from numba's event API.

``python -m muls.infra.compile_times [--rows N] MODULE [ARGS...]`` runs ``MODULE`` as ``python -m MODULE ARGS...`` would, in
this process, with every compilation timed, and prints a table of the kernels compiled, the longest first: the CPU
seconds of the compiling thread spent in each kernel's own compilation (those of the kernels it compiles in
excluded), the signatures compiled, and the total. A kernel loaded from numba's cache fires no compile event and
is not listed, so a second run with the same cache lists none. ``XDG_CACHE_HOME`` (or ``NUMBA_CACHE_DIR``) pointed at
an empty folder measures a first run (:mod:`muls.infra.runtime`). For example::

    XDG_CACHE_HOME=$(mktemp -d) python -m muls.infra.compile_times scanner_sim.cli run cable_survey --out /tmp/run
"""

from __future__ import annotations

import runpy
import sys
import threading
import time
from collections import defaultdict

from numba.core import event

#: Kernels listed by name in the printed table; the rest are summed on one line.
TABLE_ROWS = 25


class CompileTimes(event.Listener):
    """Listens to numba's ``numba:compile`` events: ``own_s[name]`` the CPU seconds [s] of the compiling thread in
    each kernel's own compilation (nested compilations excluded), ``signatures[name]`` how many it compiled."""

    def __init__(self):
        self.own_s: dict[str, float] = defaultdict(float)
        self.signatures: dict[str, int] = defaultdict(int)
        self._stack = threading.local()

    def on_start(self, event) -> None:
        stack = self._frames()
        now = time.thread_time()
        if stack:
            name, started = stack[-1]
            self.own_s[name] += now - started
        dispatcher = event.data["dispatcher"]
        stack.append((f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}", now))

    def on_end(self, event) -> None:
        stack = self._frames()
        now = time.thread_time()
        name, started = stack.pop()
        self.own_s[name] += now - started
        self.signatures[name] += 1
        if stack:
            stack[-1] = (stack[-1][0], now)

    def _frames(self) -> list:
        if not hasattr(self._stack, "frames"):
            self._stack.frames = []
        return self._stack.frames

    def table(self, rows: int = TABLE_ROWS) -> str:
        """The kernels by own compile time, longest first, and the total."""
        ranked = sorted(self.own_s.items(), key=lambda item: -item[1])
        lines = [f"{'CPU s':>7}  {'sigs':>4}  kernel"]
        lines += [f"{s:7.2f}  {self.signatures[n]:4d}  {n}" for n, s in ranked[:rows]]
        if len(ranked) > rows:
            rest = ranked[rows:]
            lines.append(f"{sum(s for _, s in rest):7.2f}  {sum(self.signatures[n] for n, _ in rest):4d}  "
                         f"{len(rest)} other kernels")
        lines.append(f"{sum(self.own_s.values()):7.2f}  {sum(self.signatures.values()):4d}  "
                     f"total, {len(ranked)} kernels compiled")
        return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    rows = TABLE_ROWS
    if argv[:1] == ["--rows"] and len(argv) > 1 and argv[1].isdigit():
        rows, argv = int(argv[1]), argv[2:]
    if not argv:
        print("usage: python -m muls.infra.compile_times [--rows N] MODULE [ARGS...]", file=sys.stderr)
        return 2
    times = CompileTimes()
    event.register("numba:compile", times)
    sys.argv = argv
    code = 0
    try:
        runpy.run_module(argv[0], run_name="__main__", alter_sys=True)
    except SystemExit as stop:
        code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    finally:
        print(times.table(rows), file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
