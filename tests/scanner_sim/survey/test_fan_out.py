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
