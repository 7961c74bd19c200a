"""Multiple targets in clutter: trackers, track management (spec 05)."""

from .association import jpda_marginals
from .gnn import GNNTracker
from .jpda import JPDATracker
from .tracking import MultiTrackResult, TrackerBase, track_scans

__all__ = ["GNNTracker", "JPDATracker", "MultiTrackResult", "TrackerBase", "track_scans", "jpda_marginals"]
