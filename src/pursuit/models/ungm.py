"""The univariate nonstationary growth model (UNGM), the classic particle-filter benchmark.

Kitagawa (1987); Gordon, Salmond & Smith (1993); paper P1 eq. (15)-(16):

    x_k = a x_{k−1} + b x_{k−1} / (1 + x_{k−1}²) + c cos(ω (k − 1)) + w_k,   w_k ~ N(0, Q)
    z_k = x_k² / s + v_k,                                                     v_k ~ N(0, R)

with a = 0.5, b = 25, c = 8, ω = 1.2, s = 20.  The squared measurement makes
the posterior bimodal (the sign of x is not observed), which is what
defeats Gaussian filters.  ``k`` is the index of the step being predicted,
as for every pursuit motion model; the model is discrete-time, so ``dt`` is
accepted and ignored.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import positive
from ..rng import RNGLike, as_rng
from .measurement import _GaussianNoise

__all__ = ["UNGMMotion", "UNGMMeasurement"]


@dataclass(frozen=True)
class UNGMMotion:
    """UNGM transition x_k = a x + b x / (1 + x²) + c cos(ω (k − 1)) + w_k.

    Parameters
    ----------
    q
        Process-noise variance Q.
    a, b, c, omega
        Model constants (defaults 0.5, 25, 8, 1.2).
    """

    q: float = 1.0
    a: float = 0.5
    b: float = 25.0
    c: float = 8.0
    omega: float = 1.2

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", positive("q", self.q))
        for name in ("a", "b", "c", "omega"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise ValueError(f"{name}: expected a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))

    dim = 1

    def _forcing(self, k: int | None) -> float:
        if k is None:
            raise ValueError("k: the UNGM transition depends on the step index; pass k")
        return self.c * float(np.cos(self.omega * (int(k) - 1)))

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Noise-free transition for a batch of states ``(*b, 1)``."""
        x = np.asarray(x, dtype=float)
        # x (a + b / (1 + x²)) + forcing: one temporary, five passes
        t = np.square(x)
        t += 1.0
        np.divide(self.b, t, out=t)
        t += self.a
        t *= x
        t += self._forcing(k)
        return t

    def jacobian(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """``(*b, 1, 1)``: a + b (1 − x²) / (1 + x²)²."""
        x = np.asarray(x, dtype=float)
        x2 = x * x
        return (self.a + self.b * (1.0 - x2) / (1.0 + x2) ** 2)[..., None]

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Process-noise covariance ``[[Q]]``."""
        return np.array([[self.q]])

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """Draw x_k ~ p(x_k | x_{k−1}) for a batch of states (``rng`` may be RunStreams)."""
        xi = as_rng(rng).standard_normal(np.shape(x))
        if self.q != 1.0:
            xi *= np.sqrt(self.q)
        xi += self.f(x, k)
        return xi


@dataclass(frozen=True, eq=False)
class UNGMMeasurement(_GaussianNoise):
    """UNGM measurement z = x² / scale + v, v ~ N(0, R).

    Parameters
    ----------
    r
        Measurement-noise variance R.
    scale
        Divisor s of x² (default 20).
    """

    r: float = 1.0
    scale: float = 20.0
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "r", positive("r", self.r))
        object.__setattr__(self, "scale", positive("scale", self.scale))
        self._set_noise(np.array([[self.r]]))

    dim = 1

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, 1)``: x² / scale."""
        y = np.square(x)
        y *= 1.0 / self.scale
        return y

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, 1, 1)``: 2 x / scale."""
        return (2.0 / self.scale) * np.asarray(x, dtype=float)[..., None]
