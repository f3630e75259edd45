"""What a process does once (muls/infra/runtime.py) beyond the kernel cache (tests/muls/infra/test_kernel_cache.py):
a command's own process leaves its objects to its exit, a process that goes on keeps collecting."""

from __future__ import annotations

import gc
import subprocess
import sys

from conftest import ROOT, run_cli

#: Runs ``scanner-sim scenes`` as its console script does (``main()``, the process's own command line) and prints how
#: many objects the collector then no longer examines.
CONSOLE_SCRIPT = """
import gc, sys
from scanner_sim.cli import main
sys.argv = ["scanner-sim", "scenes"]
main()
print("frozen", gc.get_freeze_count())
"""


def test_a_command_leaves_its_objects_to_the_exit_only_in_its_own_process():
    """The interpreter's teardown of a pass's process collected 0.3 to 0.5 s of objects that die with it; the console
    scripts now freeze them as the command ends (end_of_command). A caller of ``main(argv)``, such as this test's
    process, goes on and must keep collecting: nothing of it is frozen."""
    out = subprocess.run([sys.executable, "-c", CONSOLE_SCRIPT], cwd=ROOT, capture_output=True, text=True, check=True)
    assert int(out.stdout.split("frozen")[-1]) > 10_000  # every object of the imported modules
    gc.unfreeze()
    code, printed = run_cli(["scenes"])
    assert code == 0 and "cable_survey" in printed
    assert gc.get_freeze_count() == 0
