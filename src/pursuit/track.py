"""The container for a filter's output over time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._repr import array_text, keys_text

__all__ = ["Track", "SMOOTHER_KEYS"]

SMOOTHER_KEYS = ("pred_mean", "pred_cov", "cross_cov")
"""Info keys needed only by the RTS smoother; dropped unless asked for."""


@dataclass(frozen=True)
class Track:
    """A filter's output over time.

    Attributes
    ----------
    mean
        ``(K, *batch, n)`` filtered means, step 1 to K.
    cov
        ``(K, *batch, n, n)`` filtered covariances, or ``None`` if not kept.
    info
        Step info stacked over time: ``{key: (K, *batch, ...)}``.
    name
        The filter's name.
    wall_time
        Seconds spent in ``init`` and ``step`` calls.
    """

    mean: np.ndarray
    cov: np.ndarray | None
    info: dict[str, np.ndarray] = field(default_factory=dict)
    name: str = ""
    wall_time: float = 0.0

    def __repr__(self) -> str:
        # shapes, not values: a track holds every step of every run
        return (
            f"Track({self.name!r}, mean={array_text(self.mean)}, cov={array_text(self.cov)}, "
            f"info={keys_text(self.info)}, wall_time={self.wall_time:.3g})"
        )

    @property
    def steps(self) -> int:
        """Number of time steps K."""
        return self.mean.shape[0]
