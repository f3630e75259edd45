"""Where numba caches the compiled kernels (muls/kernel_cache.py)."""

import os
import subprocess
import sys
from pathlib import Path

from muls.kernel_cache import source_key

ROOT = Path(__file__).resolve().parent.parent


def _tree(tmp_path):
    for package in ("muls", "scanner_sim"):
        (tmp_path / package / "sub").mkdir(parents=True)
        (tmp_path / package / "a.py").write_text("x = 1\n")
        (tmp_path / package / "sub" / "b.py").write_text("y = 2\n")
    return tmp_path


def test_regression_a_change_to_a_helper_module_starts_a_fresh_kernel_cache(tmp_path):
    """Root cause: numba's cache checks only the source file of the function it compiled, while a kernel compiles
    in the helpers it calls from other modules. Changing the normal draws in muls/noise.py (or the deciding test in
    muls/deciding_channels.py) alone left the digitiser's cached kernel running the old helper: results from code
    no longer in the tree. The cache directory is now keyed by every source file's size and modification time: a
    change to any file, in either package and at any depth, gives a new key; nothing else does."""
    root = _tree(tmp_path)
    key = source_key(root)
    assert source_key(root) == key and len(key) == 16
    helper = root / "muls" / "sub" / "b.py"
    stat = helper.stat()
    os.utime(helper, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    touched = source_key(root)
    assert touched != key
    (root / "scanner_sim" / "a.py").write_text("x = 10\n")
    assert source_key(root) not in (key, touched)
    (root / "notes.txt").write_text("not a source")
    (root / "muls" / "data.yaml").write_text("a: 1")
    assert source_key(root) == source_key(root)


def test_importing_muls_points_numba_at_the_cache_of_these_sources(tmp_path):
    """In a fresh process, importing muls sets numba's cache directory to <XDG_CACHE_HOME>/muls-scanner/numba/<key of
    the repository's sources>; a NUMBA_CACHE_DIR the user set wins."""
    code = "import muls, numba; print(numba.config.CACHE_DIR)"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    out = subprocess.run([sys.executable, "-c", code], env={**env, "XDG_CACHE_HOME": str(tmp_path)}, check=True,
                         capture_output=True, text=True).stdout.strip()
    assert Path(out) == tmp_path / "muls-scanner" / "numba" / source_key(ROOT)
    mine = tmp_path / "mine"
    out = subprocess.run([sys.executable, "-c", code], env={**env, "NUMBA_CACHE_DIR": str(mine)}, check=True,
                         capture_output=True, text=True).stdout.strip()
    assert Path(out) == mine
