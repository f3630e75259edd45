"""scanner-sim view RUN_DIR --serve (the serve extra, viser): a local viewer on 127.0.0.1 only, Ctrl-C ends it with 130."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import urllib.request

import numpy as np
import psutil
import pytest

from scanner_sim import io

try:
    import viser  # noqa: F401
except ImportError:
    if os.environ.get("MULS_REQUIRE_VISER"):
        raise
    pytest.skip("the serve extra (viser) is not installed (CI installs it)", allow_module_level=True)

from conftest import ROOT


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """points.las, scene.ply and trajectory.csv of a small made-up pass."""
    from test_view import OFFSET, _records

    out = tmp_path_factory.mktemp("serve")
    io.write_las(out / "points.las", _records(), offset_m=OFFSET)
    verts = np.array([[-11, -6, -0.05], [11, -6, -0.05], [11, 6, -0.05], [-11, 6, -0.05]], float) + OFFSET
    io.write_scene_ply(out / "scene.ply", verts, np.array([[0, 1, 2], [0, 2, 3]]), [40, 40], [0, 0])
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_serve_listens_on_loopback_only_and_ctrl_c_exits_130(run_dir):
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "scanner_sim.cli", "view", str(run_dir), "--serve", "--port",
                             str(port)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        lines = iter(proc.stdout.readline, "")  # viser's own banner, then ours once the server listens
        line = next((text for text in lines if text.startswith("http://")), "")
        assert line.startswith(f"http://127.0.0.1:{port} "), (line, proc.stderr.read() if proc.poll() else "")
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        listening = {c.laddr.ip for c in psutil.Process(proc.pid).net_connections(kind="inet")
                     if c.status == psutil.CONN_LISTEN}
        assert listening == {"127.0.0.1"}
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 130
        err = proc.stderr.read().strip()
        assert "\n" not in err, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_html_and_serve_together_are_one_line(run_dir, capsys):
    from scanner_sim.cli import main

    assert main(["view", str(run_dir), "--html", "--serve"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--html and --serve" in err
    assert not (run_dir / "view.html").exists()
