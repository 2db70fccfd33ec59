"""How much memory a request would take, checked before anything is allocated (not part of the
paper's method: the boundary of the public functions). :func:`check_memory` compares an estimate
of the arrays that a size a user types makes (``max_steps``, a batch's scene count, the N of the
N-point model, an arm's segment count) with the memory this process can have
(:func:`available_memory`: the host's available memory within a container's limit, and a GPU's
free memory where the arrays live there), and raises a ``ValueError`` naming the field instead of
letting the allocation fail deep inside XLA. The estimates cover the library's arrays, not XLA's
temporaries: the check refuses what cannot fit, it does not promise that everything below will."""

from __future__ import annotations

import os

__all__ = ["available_memory", "fmt_bytes", "check_memory"]


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_available() -> int | None:
    """A cgroup v2 (or v1) memory limit less its usage, or None where there is none."""
    for limit_path, usage_path in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_path, encoding="ascii") as fh:
                text = fh.read().strip()
            if text == "max":
                return None
            limit = int(text)
            with open(usage_path, encoding="ascii") as fh:
                usage = int(fh.read().strip())
        except (OSError, ValueError):
            continue
        if limit >= 1 << 60:  # cgroup v1's "no limit"
            return None
        return max(limit - usage, 0)
    return None


def available_memory(on_device: bool = True) -> int | None:
    """Bytes this process can still allocate: the host's available memory (within a
    container's cgroup limit), and with ``on_device`` on an accelerator backend the
    smaller of that and the first device's free memory. None where unknown."""
    known = [x for x in (_meminfo_available(), _cgroup_available()) if x is not None]
    avail = min(known) if known else None
    if on_device:
        import jax

        try:
            dev = jax.devices()[0]
            stats = dev.memory_stats() if dev.platform != "cpu" else None
        except Exception:  # noqa: BLE001 - a backend without memory statistics
            stats = None
        if stats and "bytes_limit" in stats:
            free = int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
            avail = free if avail is None else min(avail, free)
    return avail


def fmt_bytes(n: float) -> str:
    """A byte count in kB, MB, GB or TB (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


# Bytes below which check_memory does not read the memory available.
SMALL_REQUEST = 16 * 2**20


def check_memory(need: float, field: str, what: str, hint: str, on_device: bool = True) -> None:
    """A ValueError naming ``field`` when ``need`` bytes (an estimate of ``what``) exceed the
    memory available (:func:`available_memory`); ``hint`` says what to do instead. A request
    under :data:`SMALL_REQUEST` passes unread: reading the memory available costs more than a
    small plan's host work, and a process without that much memory fails before it gets here."""
    if need < SMALL_REQUEST:
        return
    avail = available_memory(on_device)
    if avail is not None and need > avail:
        raise ValueError(f"{field} is too large: {what} would need about {fmt_bytes(need)} of memory, "
                         f"more than the {fmt_bytes(avail)} available; {hint}")
