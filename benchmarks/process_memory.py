"""This process's memory, for the benchmarks' figures (Linux ``/proc`` and ``getrusage``)."""

from __future__ import annotations

import resource
from pathlib import Path


def rss_mib(field: str = "VmRSS") -> float:
    """This process's current (``VmRSS``) or peak (``VmHWM``) resident set, MiB; NaN where
    ``/proc/self/status`` lacks it. Prefer ``VmHWM`` to :func:`peak_rss_mib` in a process
    started by fork and exec: ``ru_maxrss`` carries the parent's peak over them."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def peak_rss_mib() -> float:
    """Peak resident set size of this process so far (``ru_maxrss``), MiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
