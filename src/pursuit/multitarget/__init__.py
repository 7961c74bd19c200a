"""Multi-target tracking: unlabelled detections in clutter, batched over Monte Carlo runs (docs/multi-target.md)."""

from .detections import CLUTTER, PADDING, MultiTargetTruth, Scans, pad_scans

__all__ = ["Scans", "MultiTargetTruth", "pad_scans", "CLUTTER", "PADDING"]
