"""A pass's sinks fed side by side (scanner_sim/survey/fan_out.py): each takes every chunk, in the pass's order,
whatever the others do, and a sink's error reaches the pass."""

from __future__ import annotations

import threading
import time

import pytest

from scanner_sim.survey.fan_out import SinkThreads


class Recorder:
    def __init__(self, delay_s: float = 0.0):
        self.seen, self.threads, self.delay_s = [], set(), delay_s

    def add(self, chunk) -> None:
        time.sleep(self.delay_s * (chunk % 3))  # uneven: a sink running ahead of another must not reorder either
        self.seen.append(chunk)
        self.threads.add(threading.get_ident())


def test_every_sink_takes_every_chunk_in_order_on_its_own_thread():
    sinks = [Recorder(0.002), Recorder(), Recorder(0.001)]
    with SinkThreads(sinks) as fan:
        for chunk in range(40):
            fan.add(chunk)
        fan.finish()
    assert all(s.seen == list(range(40)) for s in sinks)
    assert all(len(s.threads) == 1 for s in sinks)
    assert len(set().union(*(s.threads for s in sinks))) == 3
    assert threading.get_ident() not in set().union(*(s.threads for s in sinks))


def test_a_sinks_error_reaches_the_pass():
    class Broken:
        def add(self, chunk):
            if chunk == 3:
                raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space"), SinkThreads([Recorder(), Broken()]) as fan:
        for chunk in range(10):
            fan.add(chunk)
        fan.finish()


def test_a_thread_bound_sink_takes_its_chunks_on_the_callers_thread():
    """A ROS 2 bag's sqlite3 storage refuses a connection used from another thread than the one that opened it
    (``sqlite3.ProgrammingError``): such a sink stays on the pass's thread, in order, beside the others."""
    bound, free = Recorder(), Recorder()
    bound.thread_bound = True
    with SinkThreads([bound, free]) as fan:
        for chunk in range(12):
            fan.add(chunk)
        fan.finish()
    assert bound.seen == free.seen == list(range(12))
    assert bound.threads == {threading.get_ident()} and free.threads != {threading.get_ident()}


def test_profile_sees_the_sinks_when_they_run_on_the_callers_thread():
    """``bench --profile`` read 0 s for the coverage and LAS stages once the sinks moved to threads of their own:
    cProfile sees only the thread that enabled it. With ``threads=False`` every sink takes its chunks, in order, on
    the caller's thread."""
    sinks = [Recorder(), Recorder(0.001)]
    with SinkThreads(sinks, threads=False) as fan:
        for chunk in range(12):
            fan.add(chunk)
        fan.finish()
    assert all(s.seen == list(range(12)) and s.threads == {threading.get_ident()} for s in sinks)


def test_a_pass_gives_the_same_bytes_with_its_sinks_on_threads_or_on_its_own(tmp_path, monkeypatch):
    """Sinks take their chunks on threads of their own from SINK_THREADS_FROM_WORKERS chunk workers, else on the
    pass's thread (on 2 cores their threads only took cores from the chunks): either way every file holds the same
    bits and the summary the same figures."""
    from scanner_sim.config import load_scene
    from scanner_sim.perf.pass_hashes import pass_hashes
    from scanner_sim.survey import pipeline
    from scanner_sim.survey.setup import PassOptions

    options = PassOptions(max_pulses=3000, waveforms=8, progress=False, render=False, write_scene=False)
    results = {}
    for threads_from in (1, 10**6):  # always on threads, never
        monkeypatch.setattr(pipeline, "SINK_THREADS_FROM_WORKERS", threads_from)
        out = tmp_path / str(threads_from)
        summary = pipeline.run_pass(load_scene("cable_survey"), out, options).summary
        figures = {k: v for k, v in summary.items() if not k.endswith("_s") and k not in ("pulses_per_s", "created")}
        results[threads_from] = pass_hashes(out), figures
    assert results[1] == results[10**6]
    assert set(results[1][0]) == {"points", "dropouts", "waveforms"}
