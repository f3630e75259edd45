"""PassQueue (scanner_sim/runs/jobs.py; a plan's confirmations, docs/planning.md): passes handed in over time come
back in the order they finish, and one put while others run starts at once. The tasks here are gated stand-ins for
passes on an in-process Dask client, so the order is set by the test, not by how long a pass takes."""

import json
import threading

from dask.distributed import Client

from scanner_sim.config import load_scene
from scanner_sim.runs import jobs
from scanner_sim.runs.tasks import PassFiles, PassJob
from scanner_sim.survey.setup import PassOptions

#: Per stand-in pass: set when its task starts, and the gate the test opens to let it finish (module-level: the
#: in-process client still pickles a task, so it names its function, which finds these by name).
STARTED: dict[str, threading.Event] = {}
GATES: dict[str, threading.Event] = {}


def stand_in(name: str) -> PassFiles:
    """A pass's task: started, then its files once the test opens its gate."""
    STARTED[name].set()
    assert GATES[name].wait(60)
    return PassFiles({"summary.json": json.dumps({"pass": name}).encode()})


def test_passes_come_back_as_they_finish_and_one_put_meanwhile_runs_at_once(monkeypatch, tmp_path):
    for name in ("long", "short", "then"):
        STARTED[name], GATES[name] = threading.Event(), threading.Event()
    monkeypatch.setattr(jobs, "submit_pass", lambda client, job, **_: client.submit(stand_in, job.name, pure=False))
    config = load_scene("cable_survey")

    def job(name):
        return PassJob(name, config, PassOptions(progress=False, render=False))

    with Client(processes=False, n_workers=1, threads_per_worker=3, dashboard_address=None) as client:
        queue = jobs.PassQueue(tmp_path, client, progress=False, checked=True)
        queue.put(job("long"))
        queue.put(job("short"))
        GATES["short"].set()
        key, outcome = queue.next_finished()
        assert (key, outcome.status) == ("short", "ran")
        queue.put(job("then"))
        assert STARTED["then"].wait(60) and not GATES["long"].is_set()  # it runs while the first pass still does
        GATES["then"].set()
        assert queue.next_finished()[0] == "then"
        GATES["long"].set()
        key, outcome = queue.next_finished()
        assert (key, outcome.summary, queue.pending()) == ("long", {"pass": "long"}, 0)
    assert json.loads((tmp_path / "long" / "summary.json").read_text()) == {"pass": "long"}


def test_without_a_client_the_earliest_put_runs_first(monkeypatch, tmp_path):
    ran = []

    def compute(job):
        ran.append(job.name)
        return PassFiles({"summary.json": json.dumps({"pass": job.name}).encode()})

    monkeypatch.setattr(jobs, "compute_pass", compute)
    config = load_scene("cable_survey")
    queue = jobs.PassQueue(tmp_path, progress=False, checked=True)
    for name in ("a", "b"):
        queue.put(PassJob(name, config, PassOptions(progress=False, render=False)), name.upper())
    assert ran == []  # nothing runs before it is taken
    assert [key for key, _ in queue.finished()] == ["A", "B"] and ran == ["a", "b"]
