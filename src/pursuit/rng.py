"""Random streams: one generator for a whole batch, or one per Monte Carlo run.

Every pursuit function that draws takes an ``rng`` argument.  It may be

* ``None`` or an ``int`` or a ``SeedSequence``: turned into a fresh
  ``numpy.random.Generator``;
* a ``numpy.random.Generator``: one stream for the whole batch;
* a :class:`RunStreams`: one independent generator per entry of the leading
  batch axis.  The Monte Carlo engine always uses this form, so that run ``i``
  draws exactly the same numbers whether it is computed alone, in a chunk of
  ten or in a batch of ten thousand.

Both forms answer the same calls (``standard_normal``, ``random``,
``uniform``, ``integers``, ``permutations``), so filters and models draw with
one line of code and never loop over runs themselves.
"""

from __future__ import annotations

from typing import Callable, Sequence, Union

import numpy as np

__all__ = ["RunStreams", "RNGLike", "Size", "as_rng", "permutations", "run_seed", "run_streams"]

Size = Union[int, Sequence[int]]
"""A draw's shape: an int or a sequence of ints (for :class:`RunStreams`, the first is the number of runs)."""


class RunStreams:
    """Independent random generators, one per leading batch index.

    Parameters
    ----------
    generators
        One ``numpy.random.Generator`` per run.

    Notes
    -----
    A draw of shape ``(M, *rest)`` takes ``rest``-shaped draws from each of the
    ``M`` generators in order.  The cost is one NumPy call per run (about
    1 µs), independent of the size of ``rest``.
    """

    __slots__ = ("generators",)

    def __init__(self, generators: Sequence[np.random.Generator]):
        self.generators = tuple(generators)
        for g in self.generators:
            if not isinstance(g, np.random.Generator):
                raise TypeError(f"RunStreams needs numpy Generators, got {type(g).__name__}")

    def __len__(self) -> int:
        return len(self.generators)

    def __getitem__(self, item: slice) -> "RunStreams":
        return RunStreams(self.generators[item])

    def __repr__(self) -> str:
        return f"RunStreams({len(self)} runs)"

    def _check(self, size: Size | None) -> tuple[int, ...]:
        if size is None:
            raise ValueError(f"size: RunStreams needs a size whose first entry is the number of runs ({len(self)})")
        size = (size,) if np.isscalar(size) else tuple(size)
        if len(size) == 0 or size[0] != len(self.generators):
            raise ValueError(
                f"RunStreams holds {len(self.generators)} streams; a draw must have that many rows, got size {size}"
            )
        return size

    def _fill(self, size: Size, draw: Callable[[np.random.Generator, np.ndarray], None]) -> np.ndarray:
        size = self._check(size)
        out = np.empty(size, dtype=float)
        # a (runs,)-shaped draw fills one-element rows (a 0-d row is not writable)
        for g, row in zip(self.generators, out.reshape(size[0], -1)):
            draw(g, row)
        return out

    def standard_normal(self, size: Size) -> np.ndarray:
        """Standard normal draws, row i from run i's generator.

        Parameters
        ----------
        size
            Output shape; ``size[0]`` must be the number of runs (an int is
            the shape ``(size,)``).

        Returns
        -------
        np.ndarray
            float64 draws of shape ``size``.

        Raises
        ------
        ValueError
            If ``size[0]`` is not the number of runs.
        """
        return self._fill(size, lambda g, row: g.standard_normal(out=row))

    def random(self, size: Size) -> np.ndarray:
        """Uniform draws on [0, 1), row i from run i's generator.

        Parameters
        ----------
        size
            Output shape; ``size[0]`` must be the number of runs.

        Returns
        -------
        np.ndarray
            float64 draws of shape ``size``.

        Raises
        ------
        ValueError
            If ``size[0]`` is not the number of runs.
        """
        return self._fill(size, lambda g, row: g.random(out=row))

    def uniform(self, low: float = 0.0, high: float = 1.0, size: Size | None = None) -> np.ndarray:
        """Uniform draws on [low, high), row i from run i's generator.

        Parameters
        ----------
        low, high
            The interval (scalars).
        size
            Output shape; ``size[0]`` must be the number of runs (required;
            the default None exists only to match ``Generator.uniform``).

        Returns
        -------
        np.ndarray
            float64 draws of shape ``size``.

        Raises
        ------
        ValueError
            If ``size`` is None or ``size[0]`` is not the number of runs.
        """
        u = self.random(size)
        return low + (high - low) * u

    def integers(self, low: int, high: int | None = None, size: Size | None = None) -> np.ndarray:
        """Integer draws, row i from run i's generator, as ``Generator.integers``.

        Parameters
        ----------
        low, high
            Draws lie in [low, high); with ``high`` None, in [0, low).
        size
            Output shape; ``size[0]`` must be the number of runs (required).

        Returns
        -------
        np.ndarray
            int64 draws of shape ``size``.

        Raises
        ------
        ValueError
            If ``size`` is None or ``size[0]`` is not the number of runs.
        """
        size = self._check(size)
        rows = [g.integers(low, high, size=size[1:]) for g in self.generators]
        return np.stack(rows)

    def permutations(self, n: int, size: Size) -> np.ndarray:
        """Independent random permutations of ``range(n)``, row i from run i's generator.

        Parameters
        ----------
        n
            Length of each permutation.
        size
            Shape of the batch of permutations; ``size[0]`` must be the
            number of runs.

        Returns
        -------
        np.ndarray
            Integer array of shape ``(*size, n)``; each last-axis row is a
            permutation of ``0 .. n-1``.

        Raises
        ------
        ValueError
            If ``size[0]`` is not the number of runs.
        """
        size = self._check(size)
        return np.stack([_permutations(g, n, size[1:]) for g in self.generators])


def _permutations(g: np.random.Generator, n: int, size: tuple[int, ...]) -> np.ndarray:
    base = np.broadcast_to(np.arange(n), (*size, n))
    return g.permuted(base, axis=-1)


RNGLike = Union[None, int, np.random.SeedSequence, np.random.Generator, RunStreams]


def as_rng(rng: RNGLike) -> np.random.Generator | RunStreams:
    """Normalise an ``rng`` argument to a Generator or a :class:`RunStreams`."""
    if isinstance(rng, (np.random.Generator, RunStreams)):
        return rng
    if rng is None or isinstance(rng, (int, np.integer, np.random.SeedSequence)):
        return np.random.default_rng(rng)
    raise TypeError(f"rng must be None, an int, a SeedSequence, a Generator or RunStreams, got {type(rng).__name__}")


def permutations(rng: np.random.Generator | RunStreams, n: int, size: Size) -> np.ndarray:
    """Random permutations of ``range(n)`` from either rng form.

    Parameters
    ----------
    rng
        One Generator for the whole batch, or :class:`RunStreams` (then
        ``size[0]`` must be the number of runs and row i is drawn from run
        i's generator).
    n
        Length of each permutation.
    size
        Shape of the batch of permutations (an int is ``(size,)``).

    Returns
    -------
    np.ndarray
        Integer array of shape ``(*size, n)``; each last-axis row is a
        permutation of ``0 .. n-1``.
    """
    if isinstance(rng, RunStreams):
        return rng.permutations(n, size)
    size = (size,) if np.isscalar(size) else tuple(size)
    return _permutations(rng, n, size)


def run_seed(root: int | np.random.SeedSequence, run: int) -> np.random.SeedSequence:
    """The seed of Monte Carlo run ``run`` under root seed ``root``.

    Identical to ``SeedSequence(root).spawn(run + 1)[run]`` but needs no
    spawning of the runs before it, so any chunk of runs can be seeded
    independently.
    """
    if isinstance(root, np.random.SeedSequence):
        entropy, key = root.entropy, tuple(root.spawn_key)
    else:
        entropy, key = int(root), ()
    return np.random.SeedSequence(entropy, spawn_key=(*key, int(run)))


def run_streams(root: int | np.random.SeedSequence, runs: Sequence[int], purpose: int) -> RunStreams:
    """Per-run generators for ``runs``; ``purpose`` separates independent uses.

    Purpose 0 is the scenario (truth and measurements, shared by all filters:
    common random numbers); purpose 1 is the filters' own randomness, also
    the same stream for every filter compared.
    """
    gens = []
    for r in runs:
        child = run_seed(root, r)
        ss = np.random.SeedSequence(child.entropy, spawn_key=(*child.spawn_key, int(purpose)))
        gens.append(np.random.Generator(np.random.PCG64(ss)))
    return RunStreams(gens)
