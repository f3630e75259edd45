"""Where numba keeps the compiled kernels: one directory per state of the package's sources.

numba's on-disk cache (``cache=True``) checks only the source file of the function it compiled, but a kernel
compiles in the helpers it calls from other modules (:mod:`muls.noise`'s draws and
:mod:`muls.deciding_channels` in :mod:`muls.detection`'s digitiser, :mod:`muls.waveform`'s column in the peak
search). After a change to such a helper alone (an edit, or a ``git pull`` into an editable install) the cached
kernel would go on running the old helper, silently. So the cache directory is keyed by the size and modification
time of every source file of ``muls`` and ``scanner_sim``: any change starts a fresh cache, and the first run after
it compiles again. Importing :mod:`muls` sets it, before any kernel is defined; ``NUMBA_CACHE_DIR``, if set, wins.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import time
from pathlib import Path

import numba

#: The packages whose sources key the cache (both hold kernels; scanner_sim's call muls's).
PACKAGES = ("muls", "scanner_sim")
#: [s] Caches of other source states left untouched this long are removed (a few MB each).
STALE_AFTER_S = 7 * 24 * 3600


def source_key(root: Path) -> str:
    """16 hex digits from the relative path, size and modification time of every ``.py`` file of
    :data:`PACKAGES` under ``root``."""
    digest = hashlib.sha1()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            stat = path.stat()
            digest.update(f"{path.relative_to(root)}:{stat.st_size}:{stat.st_mtime_ns}\n".encode())
    return digest.hexdigest()[:16]


def kernel_cache_dir() -> Path | None:
    """The directory numba caches this package's kernels in, or None where numba keeps them beside the sources
    (``__pycache__``, its default, used when the user cache directory cannot be written)."""
    return Path(numba.config.CACHE_DIR) if numba.config.CACHE_DIR else None


def configure() -> None:
    """Point numba's cache at ``$XDG_CACHE_HOME/muls-scanner/numba/<source key>`` (``~/.cache`` by default),
    unless ``NUMBA_CACHE_DIR`` is set or that directory cannot be written; remove the caches of other source
    states unused for :data:`STALE_AFTER_S`."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "muls-scanner" / "numba"
    path = base / source_key(Path(__file__).resolve().parent.parent)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError:
        return
    numba.config.CACHE_DIR = str(path)
    for other in base.iterdir():
        if other != path and other.stat().st_mtime < time.time() - STALE_AFTER_S:
            shutil.rmtree(other, ignore_errors=True)


configure()
