"""What memory this host has free for a process: the kernel's ``MemAvailable``, or less where the process's
cgroup (a container's limit) leaves less (:func:`cpu_free_bytes`). A leaf module, torch-free: a fit sizes its grids
by it (:mod:`pytest_n2r.fit.free_memory`), a reader of scene files what a file declares (``scene/memory_guard.py``).

Convention
----------
Bytes. ``MemAvailable`` from ``/proc/meminfo`` (what can be allocated without swapping, page cache included);
cgroup headroom: v2 ``memory.max`` − ``memory.current``, v1 ``memory.limit_in_bytes`` − ``memory.usage_in_bytes``,
the tightest over the cgroup and its ancestors, usage counted without the inactive file cache the kernel reclaims
first (as ``docker stats`` does).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["cpu_free_bytes"]

#: Where the kernel lists this process's cgroups, and where their files are (module constants for the tests).
_PROC_CGROUP = Path("/proc/self/cgroup")
_CGROUP_ROOT = Path("/sys/fs/cgroup")


def cpu_free_bytes() -> int | None:
    """The bytes this process may still allocate on the CPU (see the Convention); ``None`` where the system does
    not say."""
    known = [b for b in (_meminfo_available(), _cgroup_free()) if b is not None]
    return min(known) if known else None


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_free() -> int | None:
    """The least headroom under this process's cgroup memory limits and their ancestors' (usage counted
    without the inactive file cache the kernel reclaims first, as ``docker stats`` does)."""
    try:
        lines = _PROC_CGROUP.read_text().splitlines()
    except OSError:
        return None
    free = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, path = parts
        if controllers == "":
            base, limit_file, usage_file, cache_key = _CGROUP_ROOT, "memory.max", "memory.current", "inactive_file"
        elif "memory" in controllers.split(","):
            base, limit_file, usage_file, cache_key = (_CGROUP_ROOT / "memory", "memory.limit_in_bytes",
                                                       "memory.usage_in_bytes", "total_inactive_file")
        else:
            continue
        folder = base / path.lstrip("/")
        while folder != base.parent:
            limit, usage = _read_int(folder / limit_file), _read_int(folder / usage_file)
            if limit is not None and usage is not None:
                free.append(limit - usage + _stat_value(folder / "memory.stat", cache_key))
            folder = folder.parent
    return min(free) if free else None


def _read_int(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None  # absent, or "max": no limit


def _stat_value(path: Path, key: str) -> int:
    try:
        for line in path.read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key:
                return int(value)
    except (OSError, ValueError):
        pass
    return 0
