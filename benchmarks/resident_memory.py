"""Resident memory of this process, read from Linux's ``/proc/self``, for the benchmarks that measure
the peak of one section of a run (``bench_rasterize.py``, ``cost_curves.py``)."""

from __future__ import annotations

from pathlib import Path


def status_mib(field: str) -> float:
    """A memory line of ``/proc/self/status`` in MiB: ``VmRSS`` (resident now), ``VmHWM`` (the peak mark)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    raise KeyError(field)


def reset_peak_rss() -> float:
    """Restart the peak mark (``VmHWM``) from the resident size now, so that the peak read after a section
    is the section's, not that of the set-up before it; returns the resident size now in MiB."""
    Path("/proc/self/clear_refs").write_text("5")
    return status_mib("VmRSS")
