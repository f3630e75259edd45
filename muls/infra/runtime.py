"""The process's runtime set-up, in one place: where numba caches the compiled kernels, how OpenMP's idle workers
wait, and how glibc keeps chunk-sized arrays. Importing a module changes nothing here: kernels are defined with
:func:`kernel`, and entry points (the two command lines, a pass's set-up, a Dask task) call
:func:`configure_process` once.

**Kernel cache.** numba's on-disk cache (``cache=True``) checks only the source file of the function it compiled,
but a kernel compiles in the helpers it calls from other modules (:mod:`muls.infra.noise`'s draws and
:mod:`muls.receiver.deciding_channels` in :mod:`muls.receiver.digitiser`'s digitiser,
:mod:`muls.optics.optical_model`'s column in the peak search). After a change to such a helper alone (an edit, or
a ``git pull`` into an editable install) a cached kernel would go on running the old helper, silently. So
:func:`kernel` caches each kernel in a directory keyed by
the size and modification time of every source file of ``muls`` and of the package that defines the kernel (a
package that builds on muls, such as the mission, registers its own sources by defining its kernels with
:func:`kernel`): any change starts a fresh cache, and the first run after it compiles again.
``NUMBA_CACHE_DIR``, if set, wins.

**Threads.** A pass runs chunks side by side, each on one thread, beside numba's parallel kernels (the Monte
Carlo's; OpenMP threading layer). By default an OpenMP worker keeps spinning for a while after each parallel region and so takes a
core from the threads beside it for nothing; with ``OMP_WAIT_POLICY=PASSIVE`` idle workers sleep at once.
Measured on the 2-core machine (``fast`` on cable_survey, 200,000 pulses, the chunk loop alone): 112,000 and
132,000 pulses/s spinning against 134,000 and 160,000 passive, at fewer cores used. The policy is read when OpenMP
loads (numba's first parallel launch); a value the user set wins.

**Memory.** glibc returns large freed arrays to the OS and page-faults them anew for the next chunk. Measured with
a profiler on the 2-core machine (``scanner-sim bench-rays``, 20,000 pulses x 19 sub-rays): the geometry stage's
fresh multi-megabyte arrays were each mmapped and page-faulted anew per chunk, which cost as much as 25 ms of
175 ms; with the thresholds below the memory is reused and the hit kernel halves.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

#: The package every kernel's cache key includes (every kernel may compile in its helpers).
PHYSICS_PACKAGE = "muls"
#: [s] Caches of other source states left untouched this long are removed (a few MB each).
STALE_AFTER_S = 7 * 24 * 3600
#: The OpenMP wait policy set unless the environment has one.
OMP_WAIT_POLICY = "PASSIVE"
#: [bytes] glibc's mmap and trim thresholds while a pass runs (``mallopt``).
MMAP_THRESHOLD_BYTES = 64 << 20
TRIM_THRESHOLD_BYTES = 512 << 20

_lock = threading.Lock()
_keys: dict[tuple[str, ...], str] = {}
_configured = False


def source_key(roots) -> str:
    """16 hex digits from the relative path, size and modification time of every ``.py`` file under each package
    folder of ``roots`` (an iterable of paths)."""
    digest = hashlib.sha1()
    for root in roots:
        root = Path(root)
        for path in sorted(root.rglob("*.py")):
            stat = path.stat()
            digest.update(f"{root.name}/{path.relative_to(root)}:{stat.st_size}:{stat.st_mtime_ns}\n".encode())
    return digest.hexdigest()[:16]


def cache_base() -> Path:
    """``$XDG_CACHE_HOME/muls-scanner/numba`` (``~/.cache`` by default): the folder of every source state's cache."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "muls-scanner" / "numba"


def _package_root(name: str) -> Path:
    return Path(sys.modules[name].__file__).resolve().parent


def kernel_cache_dir(package: str) -> Path | None:
    """The directory numba caches the kernels of ``package`` in (keyed by its sources and muls's), or None where
    numba keeps them beside the sources (``NUMBA_CACHE_DIR`` unset and the user cache directory not writable)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    packages = tuple(dict.fromkeys((PHYSICS_PACKAGE, package)))
    with _lock:
        fresh = packages not in _keys
        if fresh:
            _keys[packages] = source_key(_package_root(p) for p in packages)
    path = cache_base() / _keys[packages]
    try:
        path.mkdir(parents=True, exist_ok=True)
        if fresh:  # in use: marked so that no process takes it for stale (configure_process)
            with tempfile.TemporaryFile(dir=path):
                pass
            os.utime(path)
    except OSError:
        return None
    return path


@contextlib.contextmanager
def _cache_dir(path: Path | None):
    """numba's cache directory set to ``path`` while a kernel is defined (numba reads it then, and only then)."""
    if path is None or os.environ.get("NUMBA_CACHE_DIR"):
        yield
        return
    import numba

    with _lock:
        before = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(path)
        try:
            yield
        finally:
            numba.config.CACHE_DIR = before


def kernel(function=None, /, **options):
    """``@kernel`` or ``@kernel(nogil=True, ...)``: ``numba.njit(cache=True, **options)``, its cache in the directory
    of the defining package's sources (:func:`kernel_cache_dir`)."""

    import numba  # here, not at the top: the command lines' --help and validate import this module but no kernel

    def define(f):
        with _cache_dir(kernel_cache_dir(f.__module__.partition(".")[0])):
            return numba.njit(cache=True, **options)(f)

    return define(function) if function is not None else define


def configure_process() -> None:
    """Set up this process once (idempotent, any thread): idle OpenMP workers sleep (unless ``OMP_WAIT_POLICY`` is
    set), glibc keeps chunk-sized arrays for reuse (where mallopt exists), and kernel caches of other source states
    unused for :data:`STALE_AFTER_S` are removed."""
    global _configured
    with _lock:
        if _configured:
            return
        _configured = True
    os.environ.setdefault("OMP_WAIT_POLICY", OMP_WAIT_POLICY)
    _tune_malloc()
    _remove_stale_caches()


def end_of_command() -> None:
    """Leave this process's objects to its exit instead of to the garbage collector: at exit the interpreter tears
    the modules down one after another and collects again and again, 0.2 to 0.4 s of CPU once numba and the physics
    are imported (most of it cyclic collections of objects that die with the process anyway). Frozen, they are
    never examined again; objects still close as their last reference goes, and the atexit handlers run. Only for
    a command's own process (its console script): a process that goes on (a test calling ``main(argv)``) keeps
    collecting."""
    import gc

    gc.freeze()


def _tune_malloc() -> bool:
    """Raise glibc's mmap and trim thresholds; False where mallopt is unavailable (not glibc), which costs speed."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3  # from glibc's malloc.h
        return bool(libc.mallopt(m_mmap_threshold, MMAP_THRESHOLD_BYTES)) and bool(
            libc.mallopt(m_trim_threshold, TRIM_THRESHOLD_BYTES))
    except (OSError, AttributeError):
        return False


def release_free_heap() -> bool:
    """Give the heap's free pages back to the system (glibc's ``malloc_trim``): the raised trim threshold keeps up
    to :data:`TRIM_THRESHOLD_BYTES` of freed memory resident for reuse, which a pass that frees large arrays now and
    then (a site's windows) would otherwise carry as it goes. False where malloc_trim is unavailable (not glibc)."""
    try:
        import ctypes

        return bool(ctypes.CDLL("libc.so.6").malloc_trim(0))
    except (OSError, AttributeError):
        return False


def _remove_stale_caches() -> None:
    base = cache_base()
    if os.environ.get("NUMBA_CACHE_DIR") or not base.is_dir():
        return
    current = set(_keys.values())
    for other in base.iterdir():
        with contextlib.suppress(OSError):
            if other.name not in current and other.stat().st_mtime < time.time() - STALE_AFTER_S:
                shutil.rmtree(other, ignore_errors=True)
