"""Running filters over time and over many Monte Carlo runs."""

from .montecarlo import monte_carlo, run_chunk
from .run import run

__all__ = ["run", "monte_carlo", "run_chunk"]
