"""A pass's chunk sinks fed side by side: :class:`SinkThreads`.

The chunk threads compute a pass's chunks in parallel, but its sinks (point clouds, dropouts, running figures,
coverage, uncertainty, the picture's sample) took each chunk one after the other on the pass's main thread: 0.32 to
0.37 s for the 200,000 pulses of cable_survey on the busy 2-core machine, the LAS writer and the coverage tally
about 0.1 to 0.15 s each. However many cores compute the chunks, a pass cannot end before its sinks have taken them
all (docs/performance.md, "Cores"). Here each sink has its own thread and takes the chunks in the pass's order, as
before (so every file and figure holds the same bits), while the sinks run beside one another: the pass is bound
by its slowest sink instead of their sum, as far as numpy and the writers release the GIL.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor

#: Chunks a sink may have waiting before the main thread stops to let it catch up (what the chunks hold in memory).
BACKLOG = 2


class SinkThreads:
    """``add(chunk)`` hands the chunk to every sink, each on its own thread in the order given; :meth:`finish`
    waits for them and raises the first error a sink raised. A context manager: leaving it waits for the sinks.
    A sink with a true ``thread_bound`` attribute (one whose writer serves only the thread that opened it, such as
    sqlite3's) takes its chunks on the caller's thread instead; with ``threads=False`` every sink does (a profile of
    the caller's thread then sees the sinks' work)."""

    def __init__(self, sinks: list, threads: bool = True):
        def here(sink) -> bool:
            return not threads or getattr(sink, "thread_bound", False)

        self._here = [sink for sink in sinks if here(sink)]
        self._sinks = [sink for sink in sinks if not here(sink)]
        self._threads = [ThreadPoolExecutor(1, thread_name_prefix="sink") for _ in self._sinks]
        self._pending: deque[list[Future]] = deque()

    def add(self, chunk) -> None:
        self._pending.append([thread.submit(sink.add, chunk) for sink, thread in zip(self._sinks, self._threads)])
        for sink in self._here:
            sink.add(chunk)
        while len(self._pending) > BACKLOG:
            _wait(self._pending.popleft())

    def finish(self) -> None:
        while self._pending:
            _wait(self._pending.popleft())

    def __enter__(self) -> SinkThreads:
        return self

    def __exit__(self, *exc) -> None:
        for thread in self._threads:
            thread.shutdown(wait=True, cancel_futures=True)


def _wait(futures: list[Future]) -> None:
    for future in futures:
        future.result()
