"""Multiple targets in clutter: GNN and JPDA trackers with track management (docs/spec/05-multi-target-pmht.md §4)."""

from .association import jpda_marginals
from .gnn import GNNTracker
from .jpda import JPDATracker
from .tracking import MultiTrackResult, TrackerBase, track_scans

__all__ = ["GNNTracker", "JPDATracker", "MultiTrackResult", "TrackerBase", "track_scans", "jpda_marginals"]
