"""Multi-target tracking: detections, trackers and metrics, batched over Monte Carlo runs.

Specification: ``docs/spec/05-multi-target-pmht.md §1``.
"""

from .metrics import (
    Gospa,
    RunAverage,
    TrackCounts,
    gospa,
    gospa_assignment,
    gospa_summary,
    ospa,
    run_average,
    track_counts,
    track_switches,
)

__all__ = [
    "Gospa",
    "RunAverage",
    "TrackCounts",
    "gospa",
    "gospa_assignment",
    "gospa_summary",
    "ospa",
    "run_average",
    "track_counts",
    "track_switches",
]
