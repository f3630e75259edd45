"""What memory a command may plan on, and the refusal of a count or size whose allocation would exceed it: the
machine's available memory (``MemAvailable``, or less under a cgroup limit), of which a run may plan to use
:data:`MEMORY_SHARE`, checked before anything is allocated (``docs/errors.md``).
"""

from __future__ import annotations

from .errors import ParameterError

#: Share of the memory available when a command starts that it may plan to use (as a pass does).
MEMORY_SHARE = 0.8


def available_memory_bytes() -> int | None:
    """Memory a new allocation can take [bytes]: ``MemAvailable`` of /proc/meminfo, less under a cgroup (v2
    or v1) limit; None where neither is known."""
    found = []
    try:
        with open("/proc/meminfo") as fh:
            found += [int(line.split()[1]) * 1024 for line in fh if line.startswith("MemAvailable:")]
    except (OSError, ValueError, IndexError):
        pass
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_file) as lf, open(usage_file) as uf:
                limit, usage = int(lf.read().split()[0]), int(uf.read().split()[0])
        except (OSError, ValueError, IndexError):  # absent, or "max" (no limit)
            continue
        if limit < 1 << 60:
            found.append(max(0, limit - usage))
    return min(found) if found else None


def gb(n_bytes: float) -> str:
    """A memory size for a message: "10,150.0 GB", "350 MB"."""
    return f"{n_bytes / 1e9:,.1f} GB" if n_bytes >= 1e8 else f"{n_bytes / 1e6:,.0f} MB"


def check_memory(key: str, value, n_bytes: float, what: str, largest, available_bytes: int | None = None) -> None:
    """Refuse ``key`` = ``value`` when what it allocates, about ``n_bytes`` [bytes] (``what`` says for what),
    exceeds :data:`MEMORY_SHARE` of the available memory (``available_bytes``, default
    :func:`available_memory_bytes`; nothing is refused where it is unknown). ``largest(budget_bytes)`` says the
    value that fits, for the message. Raises :class:`ParameterError`: "<key> = <value>: <what> would need about
    X GB of memory, more than the Y GB it may use (80% of the Z GB available); <largest>"."""
    available = available_memory_bytes() if available_bytes is None else available_bytes
    if available is None or n_bytes <= MEMORY_SHARE * available:
        return
    budget = MEMORY_SHARE * available
    raise ParameterError(f"{key} = {value}: {what} would need about {gb(n_bytes)} of memory, more than the "
                         f"{gb(budget)} it may use ({MEMORY_SHARE:.0%} of the {gb(available)} available); "
                         f"{largest(budget)}")
