"""Multi-target tracking: detections, trackers and metrics, batched over Monte Carlo runs.

Specification: ``docs/spec/05-multi-target-pmht.md`` (§1 detections, §4 trackers and GM-PHD, §5 metrics).
"""

from .association import jpda_marginals
from .detections import CLUTTER, PADDING, MultiTargetTruth, Scans, pad_scans
from .epmht import EPMHTTracker
from .gmphd import GMPHDResult, GMPHDTracker
from .gnn import GNNTracker
from .jpda import JPDATracker
from .mmpmht import MMPMHTTracker
from .pmht import PMHTResult, PMHTTracker
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
from .tracking import MultiTrackResult, ScanTracks, TrackerBase, track_scans, track_stream

__all__ = [
    "CLUTTER",
    "MultiTargetTruth",
    "PADDING",
    "Scans",
    "pad_scans",
    "EPMHTTracker",
    "GMPHDResult",
    "GMPHDTracker",
    "GNNTracker",
    "Gospa",
    "JPDATracker",
    "MMPMHTTracker",
    "MultiTrackResult",
    "PMHTResult",
    "PMHTTracker",
    "RunAverage",
    "ScanTracks",
    "TrackCounts",
    "TrackerBase",
    "gospa",
    "gospa_assignment",
    "gospa_summary",
    "jpda_marginals",
    "ospa",
    "run_average",
    "track_counts",
    "track_scans",
    "track_stream",
    "track_switches",
]
