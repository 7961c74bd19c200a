"""Source of the unrolled linear Kalman kernels, generated per model structure (no numba import here).

The block kernels of :mod:`pursuit._compiled.gauss_kernels` sweep whole
``(n, n, B)`` arrays once per matrix product, so a Kalman step streams its
temporaries through the cache several times and is bound by memory traffic
(about 300 ns per run-step on a 4-state model).  For a *linear* measurement
(``z = H x + v``), this module writes the whole predict-and-update step of
one run as straight-line scalar code: every matrix entry is a local
variable, every product is written out, and entries that the model's
structure makes zero (``F``, ``Q``, ``H``, ``R`` have fixed zero patterns,
a CV model's ``F`` is half zeros) are dropped at generation time.  The loop
over runs is innermost around that body, so the compiler vectorises it
across runs (SIMD lanes) with everything in registers; only the state and
the outputs touch memory.

The arithmetic is the Joseph-form update with missing components masked
(``pursuit.filters.gaussian``'s convention), with the product ``A P⁻ Aᵀ``
formed directly, not through a Cholesky factor as the NumPy filters and
the block kernels do (that would add an unrolled factorisation per step;
the linear cases pass ``tests/filters/test_perturbation.py`` without it):
``P⁻ = λ F P Fᵀ + Q``, ``S = H P⁻ Hᵀ + R`` on the measured components (an
unmeasured one gets ``S_aa = 1`` and no cross terms), ``K = P⁻ Hᵀ S⁻¹``
with the unmeasured columns zeroed, ``P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ``.
A run whose innovation covariance does not factor is flagged in ``ok`` for
the caller to recompute with NumPy, as in the block kernels.

Three kernels come from one body, so they give the same bits: ``sequence``
(all steps of a block of runs, the state kept in one flat workspace, the
results written in the track's layout) and ``step`` (one step, lane-major
inputs, every result in one lane-major output array whose row ranges
:func:`step_rows` gives, the prediction and cross-covariance the smoother
needs included) and ``one`` (one step of one run, for a filter stepped one
run at a time from Python: few arguments, since numba's dispatcher costs
about a tenth of a microsecond per argument, and the model packed in one
vector, :func:`one_constants`).  ``sequence`` and ``step`` are serial,
release the GIL and take a range of blocks ``[b0, b1)``, so
:func:`pursuit._compiled.generated.run_blocks` can share the blocks among
threads.  Every sum of products is written with
explicit ``fma`` calls and nothing is left to the compiler's contraction,
which would otherwise depend on how often a product is used and so differ
between the two kernels.  The source is a pure function of ``(n, m)``, the
four zero patterns and the source of the helpers it inlines
(:func:`depends_digest`), so it can be cached on disk (see
:mod:`pursuit._compiled.generated`).
"""

from __future__ import annotations

import hashlib
import importlib.resources
import math
from typing import Callable

import numpy as np

__all__ = ["depends_digest", "linear_kf_source", "one_constants", "step_rows", "structure_key"]

#: Runs per block of the sequence kernel: the block's state (about 1 KB per
#: lane for n = 4) stays in the first-level caches between steps.
SEQUENCE_BLOCK = 128
#: Runs per block of the step kernel (its output rows of a block stay in the second-level cache).
STEP_BLOCK = 256

SEQUENCE_ARGS = "xinit, Pinit, zs, F, Q, lam, H, R, keep_cov, means, covs, innov, S_out, nis, dof, loglik, ok, b0, b1"
STEP_ARGS = "x, P, z, valid, F, Q, lam, H, R, out, b0, b1"
ONE_ARGS = "x, P, z, c, out"


def depends_digest() -> str:
    """Hash of the compiled helpers the generated kernels import (``common.py``: ``fma``, ``log_positive``).

    It is written into every generated source, so the module's file name
    (a hash of its source, :func:`pursuit._compiled.generated.load_module`)
    changes when those helpers do.  numba keys its cache on the generated
    file alone and inlines the helpers into its machine code: without this,
    a pursuit upgrade or a checkout that changed only ``common.py`` would
    load the old arithmetic from the kernel folder, which outlives the
    installation (``~/.cache/pursuit/kernels``).
    """
    source = importlib.resources.files(__package__).joinpath("common.py").read_bytes()  # also from a zip
    return hashlib.sha256(source).hexdigest()[:16]


def structure_key(F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple:
    """``(n, m, patterns)``: what the generated source depends on (the zero patterns of F, Q, H, R)."""
    n, m = F.shape[0], H.shape[0]
    pats = tuple("".join("1" if v != 0.0 else "0" for v in np.asarray(a, dtype=float).ravel()) for a in (F, Q, H, R))
    return n, m, pats


def _mul(*factors):
    """Product of names and constants with 0 and 1 folded: a name, a tuple of names, or a constant."""
    if any(isinstance(f, float) and f == 0.0 for f in factors):
        return 0.0
    names = tuple(f for f in factors if not isinstance(f, float))
    if not names:
        return 1.0
    return names if len(names) > 1 else names[0]


def _product(t) -> str:
    return " * ".join(t) if isinstance(t, tuple) else (t if isinstance(t, str) else repr(t))


def _sum(terms):
    """Sum of terms (names, products from :func:`_mul`, constants) with the zeros dropped.

    Products after the first are accumulated with explicit ``fma`` calls and
    nothing is left to the compiler's floating-point contraction: whether it
    fuses a product depends on how often the product is used, which differs
    between the step and the sequence kernel, and they must give the same bits.
    """
    kept = [t for t in terms if not (isinstance(t, float) and t == 0.0)]
    if not kept:
        return 0.0
    acc = _product(kept[0])
    for t in kept[1:]:
        if isinstance(t, tuple):
            acc = f"fma({_product(t[:-1])}, {t[-1]}, {acc})"
        else:
            acc = f"{acc} + {_product(t)}"
    return acc


class _Writer:
    """Lines of source at one indentation; ``let`` names a value unless it is a constant."""

    def __init__(self, indent: str):
        self.indent = indent
        self.lines: list[str] = []

    def line(self, text: str) -> None:
        self.lines.append(self.indent + text)

    def let(self, name: str, expr):
        if isinstance(expr, float):
            return expr
        self.line(f"{name} = {_product(expr)}")
        return name


def _param(name: str, pattern: str, shape: tuple[int, int], symmetric: bool = False) -> dict:
    """Names of a model matrix's entries (``0.0`` where its pattern is zero)."""
    rows, cols = shape
    out = {}
    for i in range(rows):
        for j in range(cols):
            a, b = (min(i, j), max(i, j)) if symmetric else (i, j)
            nonzero = pattern[a * cols + b] == "1" or (symmetric and pattern[b * cols + a] == "1")
            out[i, j] = f"{name}{a}_{b}" if nonzero else 0.0
    return out


def _hoist(w: _Writer, name: str, pattern: str, shape, symmetric=False, base: int | None = None) -> dict:
    """Load every nonzero entry of matrix ``name`` into a local once; the entries of :func:`_param`.

    Read from the argument ``name[i, j]``, or with ``base`` from the packed
    vector ``c`` at ``base + i * cols + j`` (the ``one`` kernel).
    """
    entries = _param(name, pattern, shape, symmetric)
    seen = set()
    for (i, j), v in entries.items():
        if isinstance(v, str) and v not in seen:
            seen.add(v)
            source = f"{name}[{i}, {j}]" if base is None else f"c[{base + i * shape[1] + j}]"
            w.line(f"{v} = {source}")
    return entries


def _body(w: _Writer, n: int, m: int, Fe: dict, Qe: dict, He: dict, Re: dict, x: dict, P: dict, z: dict, valid: dict) -> dict:
    """The predict-and-update step of one run as straight-line code; returns the names of its results.

    ``x[i]``, ``P[i, j]`` (i ≤ j), ``z[a]`` and ``valid[a]`` are source expressions for the run's
    state and measurement (``valid[a] = None``: measured where ``z[a]`` is not NaN).  Every value is a local scalar; constants 0 and 1 are folded.
    """
    xs = {i: w.let(f"x{i}", x[i]) for i in range(n)}
    Ps = {}
    for i in range(n):
        for j in range(i, n):
            Ps[i, j] = Ps[j, i] = w.let(f"p{i}_{j}", P[i, j])
    # predict: x⁻ = F x, cross = P Fᵀ, P⁻ = λ F cross + Q (upper triangle)
    xp = {i: w.let(f"xp{i}", _sum([_mul(Fe[i, j], xs[j]) for j in range(n)])) for i in range(n)}
    cross = {(i, j): w.let(f"c{i}_{j}", _sum([_mul(Ps[i, p], Fe[j, p]) for p in range(n)])) for i in range(n) for j in range(n)}
    Pp = {}
    for i in range(n):
        for j in range(i, n):
            fpf = w.let(f"f{i}_{j}", _sum([_mul(Fe[i, p], cross[p, j]) for p in range(n)]))
            Pp[i, j] = Pp[j, i] = w.let(f"pp{i}_{j}", _sum([_mul("lam", fpf), Qe[i, j]]))
    # innovation, masked: ν_a = z_a − (H x⁻)_a where measured, else 0 (NaN in the reported innovation)
    v, e, nu = {}, {}, {}
    for a in range(m):
        za = w.let(f"zz{a}", z[a])
        v[a] = w.let(f"v{a}", f"1.0 if {valid[a] if valid[a] is not None else f'{za} == {za}'} else 0.0")
        zp = w.let(f"zp{a}", _sum([_mul(He[a, j], xp[j]) for j in range(n)]))
        d = w.let(f"d{a}", f"{za} - {zp}" if isinstance(zp, str) else f"{za} - {zp!r}")
        e[a] = w.let(f"e{a}", f"{d} if v{a} > 0.0 else np.nan")
        nu[a] = w.let(f"nu{a}", f"{d} if v{a} > 0.0 else 0.0")
    ph = {(i, a): w.let(f"ph{i}_{a}", _sum([_mul(Pp[i, j], He[a, j]) for j in range(n)])) for i in range(n) for a in range(m)}
    # S = H P⁻ Hᵀ + R on the measured pairs; an unmeasured component gets S_aa = R_aa's slot = 1
    Reff, S = {}, {}
    for a in range(m):
        for b in range(a, m):
            pzz = w.let(f"pz{a}_{b}", _sum([_mul(He[a, i], ph[i, b]) for i in range(n)]))
            both = f"v{a} > 0.0" if a == b else f"v{a} * v{b} > 0.0"
            if a == b:
                r = Re[a, a] if isinstance(Re[a, a], str) else repr(Re[a, a])
                re = w.let(f"re{a}_{b}", f"{r} if {both} else 1.0")
            else:
                re = Re[a, b] if isinstance(Re[a, b], float) else w.let(f"re{a}_{b}", f"{Re[a, b]} if {both} else 0.0")
            Reff[a, b] = Reff[b, a] = re
            masked = 0.0 if isinstance(pzz, float) else w.let(f"pm{a}_{b}", f"{pzz} if {both} else 0.0")
            S[a, b] = S[b, a] = w.let(f"s{a}_{b}", _sum([masked, re]))
    Si = _spd_inverse(w, m, S)
    # gain (unmeasured columns zeroed) and state update
    Kg = {(i, b): w.let(f"k{i}_{b}", _sum([_mul(ph[i, a], v[a], Si[a, b]) for a in range(m)])) for i in range(n) for b in range(m)}
    xo = {i: w.let(f"xo{i}", _sum([xp[i]] + [_mul(Kg[i, b], nu[b]) for b in range(m)])) for i in range(n)}
    # Joseph form: A = I − K (H masked), P = A P⁻ Aᵀ + K R Kᵀ
    hv = {(a, j): w.let(f"hv{a}_{j}", _mul(He[a, j], v[a])) for a in range(m) for j in range(n)}
    A = {}
    for i in range(n):
        for j in range(n):
            kh = w.let(f"kh{i}_{j}", _sum([_mul(Kg[i, a], hv[a, j]) for a in range(m)]))
            eye = 1.0 if i == j else 0.0
            if isinstance(kh, float):
                A[i, j] = eye - kh
            else:
                A[i, j] = w.let(f"a{i}_{j}", f"1.0 - ({kh})" if eye else f"-({kh})")
    T = {(i, j): w.let(f"t{i}_{j}", _sum([_mul(A[i, p], Pp[p, j]) for p in range(n)])) for i in range(n) for j in range(n)}
    KR = {(i, b): w.let(f"kr{i}_{b}", _sum([_mul(Kg[i, a], Reff[a, b]) for a in range(m)])) for i in range(n) for b in range(m)}
    Po = {}
    for i in range(n):
        for j in range(i, n):
            Po[i, j] = Po[j, i] = w.let(f"po{i}_{j}", _sum([_mul(T[i, p], A[j, p]) for p in range(n)]
                                                          + [_mul(KR[i, b], Kg[j, b]) for b in range(m)]))
    q = w.let("q", _sum([_mul(nu[a], Si[a, b], nu[b]) for a in range(m) for b in range(m)]))
    dd = w.let("dd", _sum([v[a] for a in range(m)]))
    return {"xo": xo, "Po": Po, "xp": xp, "Pp": Pp, "cross": cross, "e": e, "S": S, "q": q, "dd": dd}


def _spd_inverse(w: _Writer, m: int, S: dict) -> dict:
    """S⁻¹ (names) and, as locals ``det`` and ``good``, its determinant and whether S is positive definite."""
    if m == 1:
        w.line(f"det = {S[0, 0]}")
        w.line("good = det > 0.0 and det < np.inf")
        return {(0, 0): w.let("si0_0", f"1.0 / {S[0, 0]}")}
    if m == 2:  # closed form, as pursuit._linalg.inv_spd
        a, b, d = S[0, 0], S[0, 1], S[1, 1]
        bb = b if isinstance(b, str) else repr(b)
        w.line(f"det = {a} * {d} - {bb} * {bb}")
        w.line(f"good = {a} > 0.0 and det > 0.0 and det < np.inf")
        w.line("inv = 1.0 / det")
        si = {(0, 0): w.let("si0_0", f"{d} * inv"), (1, 1): w.let("si1_1", f"{a} * inv")}
        si[0, 1] = si[1, 0] = w.let("si0_1", f"-({bb}) * inv")
        return si
    # unrolled Cholesky S = L Lᵀ, then S⁻¹ = L⁻ᵀ L⁻¹
    L = {}
    goods, pivots = [], []
    for j in range(m):
        dj = w.let(f"cd{j}", _sum([S[j, j]] + [_mul(f"-{L[j, p]}", L[j, p]) if isinstance(L[j, p], str) else 0.0 for p in range(j)]))
        goods.append(f"({dj} > 0.0 and {dj} < np.inf)")
        pivots.append(dj)
        L[j, j] = w.let(f"l{j}_{j}", f"math.sqrt({dj}) if {goods[-1]} else 1.0")
        for i in range(j + 1, m):
            num = w.let(f"ln{i}_{j}", _sum([S[i, j]] + [_mul(f"-{L[i, p]}", L[j, p]) if isinstance(L[i, p], str) else 0.0 for p in range(j)]))
            L[i, j] = w.let(f"l{i}_{j}", f"{num} / {L[j, j]}" if isinstance(num, str) else 0.0)
    w.line("det = " + " * ".join(pivots))
    w.line("good = " + " and ".join(goods) + " and det < np.inf")
    Li = {}
    for j in range(m):
        Li[j, j] = w.let(f"li{j}_{j}", f"1.0 / {L[j, j]}")
        for i in range(j + 1, m):
            s = _sum([_mul(L[i, p], Li[p, j]) for p in range(j, i)])
            Li[i, j] = w.let(f"li{i}_{j}", f"-({s}) / {L[i, i]}" if isinstance(s, str) else 0.0)
    si = {}
    for a in range(m):
        for b in range(a, m):
            si[a, b] = si[b, a] = w.let(f"si{a}_{b}", _sum([_mul(Li[p, a], Li[p, b]) for p in range(b, m)]))
    return si


def _lit(v) -> str:
    return v if isinstance(v, str) else repr(v)


def _header(n: int, m: int, pats: tuple, name: str, args: str) -> tuple[_Writer, dict, dict, dict, dict]:
    w = _Writer("")
    w.line(f"def {name}({args}):")
    w.indent = "    "
    Fe = _hoist(w, "F", pats[0], (n, n))
    Qe = _hoist(w, "Q", pats[1], (n, n), symmetric=True)
    He = _hoist(w, "H", pats[2], (m, n))
    Re = _hoist(w, "R", pats[3], (m, m), symmetric=True)
    return w, Fe, Qe, He, Re


class _Rows:
    """Row offsets in a flat workspace of ``block`` lanes per row (one array, constant offsets).

    Keeping every per-lane value of a block in one 1-D array with offsets
    known at compile time lets the compiler prove that the rows never
    overlap, so the loop over lanes vectorises with a couple of runtime
    alias checks instead of one per pair of arrays (LLVM gives up beyond a
    handful).
    """

    def __init__(self, block: int):
        self.block = block
        self.count = 0

    def take(self, k: int) -> int:
        first = self.count
        self.count += k
        return first

    def at(self, row: int, lane: str = "c") -> str:
        return f"ws[{row * self.block} + {lane}]"


def _sequence_source(n: int, m: int, pats: tuple) -> list[str]:
    w, Fe, Qe, He, Re = _header(n, m, pats, "_sequence", SEQUENCE_ARGS)
    tri = {(i, j): t for t, (i, j) in enumerate((i, j) for i in range(n) for j in range(i, n))}
    stri = [(a, b) for a in range(m) for b in range(a, m)]
    rows = _Rows(SEQUENCE_BLOCK)
    rx, rP, re_, rS = rows.take(n), rows.take(len(tri)), rows.take(m), rows.take(len(stri))
    rq, rdd, rdet, rok = rows.take(1), rows.take(1), rows.take(1), rows.take(1)
    at = rows.at
    w.line("M = xinit.shape[1]")
    w.line("K = zs.shape[0]")
    w.line("for bb in range(b0, b1):")
    w.indent = "        "
    w.line(f"r0 = np.int64(bb) * {SEQUENCE_BLOCK}")
    w.line(f"B = min(r0 + {SEQUENCE_BLOCK}, M) - r0")
    w.line(f"ws = np.empty({rows.count * SEQUENCE_BLOCK})")
    # views that start at the block's first run: indices from the lane counter alone, whose bounds
    # the vectoriser can see (r0 is an argument of the outlined block, so r0 + c has none)
    w.line("xi = xinit[:, r0:r0 + B]")
    w.line("Pi = Pinit[:, :, r0:r0 + B]")
    w.line("for c in range(B):")
    for i in range(n):
        w.line(f"    {at(rx + i)} = xi[{i}, c]")
    for (i, j), t in tri.items():
        w.line(f"    {at(rP + t)} = 0.5 * (Pi[{i}, {j}, c] + Pi[{j}, {i}, c])")
    w.line(f"    {at(rok)} = 1.0")
    w.line("for k in range(K):")
    w.line(f"    zk = zs[k, r0 * {m}:(r0 + B) * {m}]")
    w.line("    for c in range(B):")
    w.indent = "                "
    res = _body(w, n, m, Fe, Qe, He, Re,
                {i: at(rx + i) for i in range(n)},
                {(i, j): at(rP + t) for (i, j), t in tri.items()},
                {a: f"zk[c * {m} + {a}]" for a in range(m)},
                {a: None for a in range(m)})
    for i in range(n):
        w.line(f"{at(rx + i)} = {_lit(res['xo'][i])}")
    for (i, j), t in tri.items():
        w.line(f"{at(rP + t)} = {_lit(res['Po'][i, j])}")
    for a in range(m):
        w.line(f"{at(re_ + a)} = {_lit(res['e'][a])}")
    for t, (a, b) in enumerate(stri):
        w.line(f"{at(rS + t)} = {_lit(res['S'][a, b])}")
    w.line(f"{at(rq)} = {_lit(res['q'])} if {_lit(res['dd'])} > 0 else np.nan")
    w.line(f"{at(rdd)} = {_lit(res['dd'])}")
    _loglik_line(w, at(rdet), res)
    w.line(f"{at(rok)} = {at(rok)} if good else 0.0")
    # the results of step k into the track's layout (runs outer, components inner): one loop per
    # output (strided stores; LLVM's cost model keeps them scalar on AVX2)
    w.indent = "            "

    def scatter(out: str, width: int, values: list[tuple[int, int]]) -> None:
        w.line(f"dst = {out}[k, r0 * {width}:(r0 + B) * {width}]")
        w.line("for c in range(B):")
        for slot, row in values:
            w.line(f"    dst[c * {width} + {slot}] = {at(row)}")

    scatter("means", n, [(i, rx + i) for i in range(n)])
    scatter("innov", m, [(a, re_ + a) for a in range(m)])
    srows = {ab: rS + t for t, ab in enumerate(stri)}
    scatter("S_out", m * m, [(a * m + b, srows[min(a, b), max(a, b)]) for a in range(m) for b in range(m)])
    w.line("if keep_cov:")
    w.indent = "                "
    scatter("covs", n * n, [(i * n + j, rP + tri[min(i, j), max(i, j)]) for i in range(n) for j in range(n)])
    w.indent = "            "
    w.line("for c in range(B):")
    w.line("    r = r0 + c")
    _finish_lines(w, "    ", at(rq), at(rdd), at(rdet), "nis[k, r]", "dof[k, r]", "loglik[k, r]")
    w.indent = "        "
    w.line("for c in range(B):")
    w.line(f"    ok[r0 + c] = {at(rok)} > 0.0")
    return w.lines


def _loglik_line(w: _Writer, dst: str, res: dict) -> None:
    """log N(ν; 0, S) over the measured components (0 where none is), in the SIMD loop (log_positive vectorises)."""
    q, dd = _lit(res["q"]), _lit(res["dd"])
    w.line(f"{dst} = -0.5 * ({q} + log_positive(det if good else 1.0) + {dd} * LOG_2PI) if {dd} > 0 else 0.0")


def _finish_lines(w: _Writer, pad: str, q: str, dd: str, ll: str, nis: str, dof: str, loglik: str) -> None:
    """NIS, degrees of freedom and log-likelihood from the workspace (a loop of its own: float → int does not vectorise)."""
    w.line(f"{pad}{nis} = {q}")
    w.line(f"{pad}{dof} = np.int64({dd})")
    w.line(f"{pad}{loglik} = {ll}")


def step_rows(n: int, m: int) -> dict[str, tuple[int, int]]:
    """Row ranges ``(first, count)`` of the step kernel's outputs in its one ``(rows, M)`` output array."""
    sizes = [("x", n), ("xp", n), ("P", n * n), ("Pp", n * n), ("cross", n * n), ("innov", m), ("S", m * m),
             ("nis", 1), ("loglik", 1), ("dof", 1), ("ok", 1)]
    out, first = {}, 0
    for name, count in sizes:
        out[name] = (first, count)
        first += count
    return out


def _step_source(n: int, m: int, pats: tuple) -> list[str]:
    w, Fe, Qe, He, Re = _header(n, m, pats, "_step", STEP_ARGS)
    rows = step_rows(n, m)
    w.line("M = x.shape[1]")
    w.line("for bb in range(b0, b1):")
    w.indent = "        "
    w.line(f"r0 = np.int64(bb) * {STEP_BLOCK}")
    w.line(f"B = min(r0 + {STEP_BLOCK}, M) - r0")
    # block views: indices from the lane counter alone; every result goes to one output array,
    # so the loop needs a few alias checks (LLVM gives up beyond a handful of arrays)
    w.line("xv = x[:, r0:r0 + B]")
    w.line("Pv = P[:, :, r0:r0 + B]")
    w.line("zv = z[:, r0:r0 + B]")
    w.line("vv = valid[:, r0:r0 + B]")
    w.line("ov = out[:, r0:r0 + B]")
    w.line("for c in range(B):")
    w.indent = "            "
    res = _body(w, n, m, Fe, Qe, He, Re,
                {i: f"xv[{i}, c]" for i in range(n)},
                {(i, j): f"0.5 * (Pv[{i}, {j}, c] + Pv[{j}, {i}, c])" for i in range(n) for j in range(i, n)},
                {a: f"zv[{a}, c]" for a in range(m)},
                {a: f"vv[{a}, c]" for a in range(m)})

    _write_outputs(w, res, rows, n, m, lambda row: f"ov[{row}, c]")
    return w.lines


def _write_outputs(w: _Writer, res: dict, rows: dict, n: int, m: int, cell: Callable[[int], str]) -> None:
    """The lines that store a step's results at the rows of :func:`step_rows`; ``cell(row)`` names the target."""

    def put(name: str, values: list) -> None:
        first, _ = rows[name]
        for t, value in enumerate(values):
            w.line(f"{cell(first + t)} = {_lit(value)}")

    put("x", [res["xo"][i] for i in range(n)])
    put("xp", [res["xp"][i] for i in range(n)])
    put("P", [res["Po"][i, j] for i in range(n) for j in range(n)])
    put("Pp", [res["Pp"][i, j] for i in range(n) for j in range(n)])
    put("cross", [res["cross"][i, j] for i in range(n) for j in range(n)])
    put("innov", [res["e"][a] for a in range(m)])
    put("S", [res["S"][a, b] for a in range(m) for b in range(m)])
    w.line(f"{cell(rows['nis'][0])} = {_lit(res['q'])} if {_lit(res['dd'])} > 0 else np.nan")
    _loglik_line(w, cell(rows["loglik"][0]), res)
    w.line(f"{cell(rows['dof'][0])} = {_lit(res['dd'])}")
    w.line(f"{cell(rows['ok'][0])} = 1.0 if good else 0.0")


def one_constants(F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray, lam: float) -> np.ndarray:
    """The model of the ``one`` kernel in one vector: ``F``, ``Q``, ``H``, ``R`` row-major, then ``λ``."""
    return np.concatenate([np.asarray(a, dtype=float).ravel() for a in (F, Q, H, R)] + [np.array([float(lam)])])


def _one_source(n: int, m: int, pats: tuple) -> list[str]:
    """``one(x (n,), P (n, n), z (m,), c, out (rows,))``: the step kernel's body for one run; returns 0, 1 or 2.

    ``z`` holding an infinity or a value beyond ±2⁵⁰⁰ returns 1 before
    anything is computed (the caller raises the NumPy step's error); else the
    results go to ``out`` at the rows of :func:`step_rows` and it returns 0,
    or 2 where a covariance does not factor (``ok`` is 0.0: the caller then
    needs no read of ``out`` to know it).
    """
    w = _Writer("")
    w.line(f"def _one({ONE_ARGS}):")
    w.indent = "    "
    w.line(f"for a in range({m}):")
    w.line(f"    if abs(z[a]) > {2.0 ** 500!r}:  # an infinity too; NaN (missing) compares False")
    w.line("        return 1")
    nn, mn = n * n, m * n
    Fe = _hoist(w, "F", pats[0], (n, n), base=0)
    Qe = _hoist(w, "Q", pats[1], (n, n), symmetric=True, base=nn)
    He = _hoist(w, "H", pats[2], (m, n), base=2 * nn)
    Re = _hoist(w, "R", pats[3], (m, m), symmetric=True, base=2 * nn + mn)
    w.line(f"lam = c[{2 * nn + mn + m * m}]")
    rows = step_rows(n, m)
    res = _body(w, n, m, Fe, Qe, He, Re,
                {i: f"x[{i}]" for i in range(n)},
                {(i, j): f"0.5 * (P[{i}, {j}] + P[{j}, {i}])" for i in range(n) for j in range(i, n)},
                {a: f"z[{a}]" for a in range(m)},
                {a: f"not math.isnan(z[{a}])" for a in range(m)})

    _write_outputs(w, res, rows, n, m, lambda row: f"out[{row}]")
    w.line("return 0 if good else 2")
    return w.lines


def linear_kf_source(n: int, m: int, pats: tuple) -> str:
    """Module source defining the jitted kernels ``sequence``, ``step`` and ``one`` and the block sizes.

    Parameters
    ----------
    n, m : int
        State and measurement dimensions.
    pats : tuple of str
        Zero patterns of ``F (n, n)``, ``Q (n, n)``, ``H (m, n)`` and ``R (m, m)``
        as strings of ``"0"``/``"1"`` in row-major order (:func:`structure_key`).

    Notes
    -----
    The kernels take the model matrices as arguments (only their zero
    patterns are baked in), so one compiled module serves every model of
    that structure; a matrix with a non-zero where its pattern says zero
    would be computed wrongly, which is why the caller keys on the pattern
    of the matrices it passes.
    """
    if n < 1 or m < 1:
        raise ValueError(f"linear_kf_source: n and m must be >= 1, got n={n}, m={m}")
    head = [
        f'"""Generated by pursuit._compiled.kf_codegen for n={n}, m={m}, patterns {pats}: do not edit."""',
        f"# compiled helpers it inlines (common.py): {depends_digest()}",
        "import math",
        "import numpy as np",
        "from numba import njit",
        "from pursuit._compiled.common import fma, log_positive",
        f"LOG_2PI = {math.log(2.0 * math.pi)!r}",
        f"SEQUENCE_BLOCK = {SEQUENCE_BLOCK}",
        f"STEP_BLOCK = {STEP_BLOCK}",
        "",
    ]
    opts = "cache=True, nogil=True, error_model='numpy'"
    tail = [
        "",
        f"sequence = njit({opts})(_sequence)",
        f"step = njit({opts})(_step)",
        "one = njit(cache=True, error_model='numpy')(_one)",
    ]
    body = _sequence_source(n, m, pats) + [""] + _step_source(n, m, pats) + [""] + _one_source(n, m, pats)
    return "\n".join(head + body + tail) + "\n"
