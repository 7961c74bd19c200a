"""Resampling schemes for particle filters, batched over runs and particles.

Every scheme takes weights ``w`` of shape ``(*batch, N)`` (normalised, or
non-negative with a positive row sum) and an ``rng`` (a
``numpy.random.Generator`` or :class:`pursuit.RunStreams`, whose leading axis
is the run axis).  The ``*_counts`` form returns how many copies of each
particle to keep, ``(*batch, N)`` with rows summing to N, which the filters
apply with one ``np.repeat`` (:func:`repeat_particles`); the plain form
returns the ``(*batch, N)`` row-local indices of the selected particles, in
ascending order.  Particle i is selected ``N w_i`` times in expectation by
all four schemes.

Nothing loops over runs or particles in Python:

* **systematic**: one uniform u₀ per row, positions (u₀ + j)/N; the number of
  positions below a cumulative weight c is ``ceil(N c − u₀)``, so the copy
  counts are differences of that, and ``np.repeat`` turns counts into
  indices.
* **stratified**: one uniform per stratum, positions (j + U_j)/N; the number
  of positions below c is ``J + [U_J < N c − J]`` with ``J = floor(N c)``.
* **multinomial**: N sorted uniforms per row from normalised cumulative sums
  of exponential spacings; each position is located among the cumulative
  weights by a stable merge sort of the two sorted rows (linear time).
* **residual**: ``floor(N w_i)`` copies deterministically, the remaining
  R = N − Σ floor(N w_i) drawn multinomially from the residual weights.

Randomness per row: systematic draws 1 uniform, stratified N, multinomial
and residual N + 1, always the same number whatever the weights, so a run's
stream does not depend on the other runs in the batch.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..rng import RunStreams
from .workspace import Workspace, scratch

__all__ = [
    "systematic",
    "stratified",
    "multinomial",
    "residual",
    "systematic_counts",
    "stratified_counts",
    "multinomial_counts",
    "residual_counts",
    "RESAMPLERS",
    "COUNTS",
    "get_resampler",
    "repeat_particles",
    "effective_sample_size",
    "counts_to_indices",
    "gather",
]


def effective_sample_size(w: np.ndarray) -> np.ndarray:
    """ESS = 1 / Σ w_i² of normalised weights ``(*batch, N)``: ``(*batch,)``."""
    return 1.0 / np.einsum("...i,...i->...", w, w)


def _cdf(w: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Cumulative weights per row, divided by the row total, last entry exactly 1.

    ``w`` may be unnormalised.

    Dividing by the last cumulative sum keeps the row non-decreasing (the
    cumulative sum of non-negative numbers is, in floating point too) and
    makes every count sum to exactly N.
    """
    c = np.cumsum(w, axis=-1, out=out)
    c /= c[..., -1:].copy()
    c[..., -1] = 1.0
    return c


def counts_to_indices(counts: np.ndarray) -> np.ndarray:
    """Turn copy counts ``(*batch, N)`` (each row summing to N) into sorted row-local indices."""
    shape = counts.shape
    N = shape[-1]
    flat = np.repeat(np.arange(counts.size), counts.reshape(-1))
    if flat.size != counts.size:
        raise ValueError("counts: every row must sum to the number of particles")
    return (flat % N).reshape(shape)


def gather(values: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Select particles per row: ``values (*batch, N, ...)``, ``idx (*batch, K)`` -> ``(*batch, K, ...)``.

    Whole rows are copied by one flat ``np.take`` along the first axis
    (about twice as fast as ``np.take_along_axis``, which indexes every
    element, and about ten times faster than fancy indexing the flat rows
    when a row holds a few numbers); the same values for ``0 ≤ idx < N``,
    which the callers guarantee (a negative index is not checked here and
    would read a neighbouring row of the flat array).
    """
    batch = idx.shape[:-1]
    N = values.shape[len(batch)]
    B = int(np.prod(batch, dtype=int))
    tail = values.shape[len(batch) + 1 :]
    offsets = (np.arange(B) * N).reshape(*batch, 1) if batch else 0
    flat = values.reshape(B * N, *tail)
    return np.take(flat, (idx + offsets).reshape(-1), axis=0).reshape(*batch, idx.shape[-1], *tail)


def systematic_counts(
    w: np.ndarray, rng: np.random.Generator | RunStreams, work: Workspace | None = None
) -> np.ndarray:
    """Copy counts ``(*batch, N)`` of systematic resampling.

    ``w`` may be unnormalised (non-negative, positive row sums).  ``work``
    holds the scratch arrays (the returned counts live in it too).
    """
    w = np.asarray(w, dtype=float)
    N = w.shape[-1]
    u0 = rng.random(w.shape[:-1])
    x = _cdf(w, scratch(work, "resample.cdf", w.shape))
    x *= N
    x -= u0[..., None]
    np.ceil(x, out=x)  # number of positions (u0 + j)/N below each cumulative weight
    return _diff_counts(x, scratch(work, "resample.counts", w.shape, np.intp))


def _diff_counts(below: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    counts = np.empty(below.shape, dtype=np.intp) if out is None else out
    counts[..., 0] = below[..., 0]
    np.subtract(below[..., 1:], below[..., :-1], out=counts[..., 1:], casting="unsafe")
    return counts


def stratified_counts(w: np.ndarray, rng: np.random.Generator | RunStreams, work: Workspace | None = None) -> np.ndarray:
    """Copy counts of stratified resampling (one uniform in each stratum [j/N, (j+1)/N))."""
    w = np.asarray(w, dtype=float)
    N = w.shape[-1]
    U = rng.random(w.shape)
    x = N * _cdf(w)
    J = np.minimum(np.floor(x), N - 1).astype(np.intp)
    below = J + (np.take_along_axis(U, J, axis=-1) < x - J)
    return _diff_counts(below)


def _sorted_uniforms(rng, shape: tuple[int, ...], count: np.ndarray | int) -> np.ndarray:
    """``count`` sorted uniforms per row, padded with 2.0 to ``shape[-1]`` entries.

    Uses normalised cumulative sums of ``shape[-1] + 1`` exponential spacings,
    always drawing the same number per row.
    """
    N = shape[-1]
    E = -np.log1p(-rng.random((*shape[:-1], N + 1)))
    s = np.cumsum(E, axis=-1)
    count = np.broadcast_to(np.asarray(count, dtype=np.intp), shape[:-1])
    total = np.take_along_axis(s, count[..., None], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = s[..., :N] / total
    return np.where(np.arange(N) < count[..., None], u, 2.0)


def _locate(c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """For sorted ``u`` and cumulative weights ``c`` per row: the bin i with c_{i−1} <= u < c_i.

    A stable sort of the concatenated rows places each c before an equal u;
    with both rows already sorted, timsort merges them in linear time.
    """
    N = c.shape[-1]
    merged = np.concatenate([c, u], axis=-1)
    order = np.argsort(merged, axis=-1, kind="stable")
    is_c = order < N
    before = np.cumsum(is_c, axis=-1)
    bins = before[~is_c].reshape(u.shape)
    return np.minimum(bins, N - 1)


def _bin_counts(bins: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """How often each particle index occurs per row: ``(*batch, N)``."""
    shape = bins.shape
    N = shape[-1]
    B = int(np.prod(shape[:-1], dtype=int))
    offsets = (np.arange(B) * N).reshape(*shape[:-1], 1) if shape[:-1] else 0
    flat = bins + offsets
    if valid is not None:
        flat = flat[valid]
    return np.bincount(flat.reshape(-1), minlength=B * N).reshape(shape)


def multinomial_counts(w: np.ndarray, rng: np.random.Generator | RunStreams, work: Workspace | None = None) -> np.ndarray:
    """Copy counts of multinomial resampling (N independent draws; Gordon et al. 1993)."""
    w = np.asarray(w, dtype=float)
    u = _sorted_uniforms(rng, w.shape, w.shape[-1])
    return _bin_counts(_locate(_cdf(w), u))


def residual_counts(w: np.ndarray, rng: np.random.Generator | RunStreams, work: Workspace | None = None) -> np.ndarray:
    """Copy counts of residual resampling: floor(N w_i), the rest multinomial (Liu & Chen 1998)."""
    w = np.asarray(w, dtype=float)
    shape = w.shape
    N = shape[-1]
    Nw = N * (w / w.sum(axis=-1, keepdims=True))
    # N w = 1 − ε from round-off must still give one deterministic copy
    det = np.floor(Nw + 1e-9)
    rest = np.maximum(N - det.sum(axis=-1), 0).astype(np.intp)  # (*batch,)
    r = np.maximum(Nw - det, 0.0)
    total = r.sum(axis=-1, keepdims=True)
    # Rows with nothing left to draw get a harmless uniform residual.
    r = np.where(total > 0, r, 1.0)
    u = _sorted_uniforms(rng, shape, rest)
    extra = _bin_counts(_locate(_cdf(r), u), u <= 1.0)
    return det.astype(np.intp) + extra


def systematic(w: np.ndarray, rng: np.random.Generator | RunStreams) -> np.ndarray:
    """Systematic resampling: one uniform per row (Kitagawa 1996; Carpenter et al. 1999)."""
    return counts_to_indices(systematic_counts(w, rng))


def stratified(w: np.ndarray, rng: np.random.Generator | RunStreams) -> np.ndarray:
    """Stratified resampling: one uniform in each stratum."""
    return counts_to_indices(stratified_counts(w, rng))


def multinomial(w: np.ndarray, rng: np.random.Generator | RunStreams) -> np.ndarray:
    """Multinomial resampling: N independent draws from the weights."""
    return counts_to_indices(multinomial_counts(w, rng))


def residual(w: np.ndarray, rng: np.random.Generator | RunStreams) -> np.ndarray:
    """Residual resampling: floor(N w_i) copies, the rest multinomial on the residuals."""
    return counts_to_indices(residual_counts(w, rng))


def repeat_particles(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Copy each particle ``counts`` times: ``values (*batch, N, ...)``, ``counts (*batch, N)``.

    One ``np.repeat`` over the flattened batch; each row's counts sum to N,
    so every row stays in place.
    """
    batch = counts.shape[:-1]
    N = counts.shape[-1]
    tail = values.shape[len(batch) + 1 :]
    B = int(np.prod(batch, dtype=int)) * N
    if tail == (1,) or tail == ():
        out = np.repeat(values.reshape(B), counts.reshape(-1))
    else:
        out = np.repeat(values.reshape(B, *tail), counts.reshape(-1), axis=0)
    return out.reshape(values.shape)


_Scheme = Callable[..., np.ndarray]

RESAMPLERS: dict[str, _Scheme] = {
    "systematic": systematic,
    "stratified": stratified,
    "multinomial": multinomial,
    "residual": residual,
}
"""Index-returning schemes by name."""

COUNTS: dict[str, _Scheme] = {
    "systematic": systematic_counts,
    "stratified": stratified_counts,
    "multinomial": multinomial_counts,
    "residual": residual_counts,
}
"""Count-returning schemes by name (what the filters use)."""


def get_resampler(name: str, counts: bool = False) -> _Scheme:
    """The scheme called ``name`` (index or count form); raises ``ValueError`` naming the field."""
    try:
        return (COUNTS if counts else RESAMPLERS)[name]
    except (KeyError, TypeError):
        raise ValueError(f"resampler: must be one of {', '.join(map(repr, RESAMPLERS))}, got {name!r}") from None
