"""The unrolled linear-KF kernels generated per model structure (pursuit._compiled.kf_codegen / generated)."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit._compiled import kf_codegen

numba = pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled import generated, particle  # noqa: E402
from pursuit.models import ConstantAcceleration, ConstantVelocity, LinearGaussian  # noqa: E402

from .test_numba_backend import _close  # noqa: E402 (the NaN, infinity and 1e-9 agreement check of the compiled tests)


def _models(case):
    rng = np.random.default_rng(11)
    if case == "cv1d-m1":
        return ConstantVelocity(ndim=1, dt=0.5, q=0.2), LinearGaussian.position(2, (0,), 0.7)
    if case == "cv2d-m2":
        return ConstantVelocity(ndim=2, dt=1.0, q=0.05), LinearGaussian.position(4, (0, 2), 1.5)
    # dense H and R: every entry of the update is live, and m = 3 takes the unrolled Cholesky path
    motion = ConstantAcceleration(ndim=2, dt=0.2, q=0.1)
    A = rng.standard_normal((3, 3))
    return motion, LinearGaussian(rng.standard_normal((3, 6)), A @ A.T + 0.5 * np.eye(3))


def _data(motion, meas, M, T, seed=5):
    rng = np.random.default_rng(seed)
    x = np.tile(np.linspace(1.0, 2.0, motion.dim), (M, 1))
    zs = np.empty((T, M, meas.dim))
    for k in range(T):
        x = motion.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    zs[2, 1, 0] = np.nan  # one missing component
    zs[4, :3] = np.nan  # nothing measured
    return zs, pu.Gaussian(np.linspace(1.0, 2.0, motion.dim), np.eye(motion.dim) * 2.0)


@pytest.mark.parametrize("case", ["cv1d-m1", "cv2d-m2", "ca2d-m3-dense"])
@pytest.mark.parametrize("sequence", [True, False])
def test_generated_kf_agrees_with_numpy(case, sequence):
    motion, meas = _models(case)
    zs, prior = _data(motion, meas, M=37, T=25)
    for fading in (1.0, 1.07):
        fast = pu.KalmanFilter(motion, meas, backend="numba", fading=fading)
        ref = pu.KalmanFilter(motion, meas, backend="numpy", fading=fading)
        a = pu.run(fast, zs, prior, keep_cov=True, sequence=sequence)
        b = pu.run(ref, zs, prior, keep_cov=True)
        _close(a.mean, b.mean, "mean")
        _close(a.cov, b.cov, "cov")
        for key in ("innovation", "S", "nis", "dof", "loglik"):
            _close(a.info[key], b.info[key], key)
    assert generated._modules, "the generated kernels were not used"


def test_run_alone_equals_run_in_batch_bitwise():
    """A run gives the same bits alone and in a batch, in the SIMD body or in the loop's scalar remainder."""
    motion, meas = _models("cv2d-m2")
    zs, prior = _data(motion, meas, M=37, T=12)
    filt = pu.KalmanFilter(motion, meas, backend="numba")
    whole = pu.run(filt, zs, prior, keep_cov=True)
    for i in (0, 5, 35, 36):
        alone = pu.run(filt, zs[:, i : i + 1], prior, keep_cov=True)
        assert np.array_equal(alone.mean[:, 0], whole.mean[:, i])
        assert np.array_equal(alone.cov[:, 0], whole.cov[:, i])
        assert np.array_equal(alone.info["loglik"][:, 0], whole.info["loglik"][:, i])


def test_indefinite_innovation_covariance_is_flagged():
    """The kernel flags runs whose S does not factor; the caller recomputes them with NumPy."""
    F, Q = np.eye(2), np.eye(2) * 0.1
    H, R = np.array([[1.0, 0.0]]), np.array([[-5.0]])  # S = P + R < 0
    mod = generated.linear_kf_kernels(F, Q, H, R)
    M, K = 3, 2
    x, P = np.zeros((2, M)), np.ascontiguousarray(np.broadcast_to(np.eye(2)[..., None], (2, 2, M)))
    outs = (np.empty((K, M * 2)), np.empty((1, 1)), np.empty((K, M)), np.empty((K, M)), np.empty((K, M)),
            np.empty((K, M), dtype=np.int64), np.empty((K, M)), np.ones(M, dtype=bool))
    mod.sequence(x, P, np.zeros((K, M)), F, Q, 1.0, H, R, False, *outs, 0, 1)
    assert not outs[-1].any()


def test_structure_key_follows_every_nonzero():
    F = np.array([[1.0, 0.5], [0.0, 1.0]])
    Q, H, R = np.eye(2), np.array([[1.0, 0.0]]), np.eye(1)
    key = kf_codegen.structure_key(F, Q, H, R)
    assert key == (2, 1, ("1101", "1001", "10", "1"))
    F2 = F.copy()
    F2[1, 0] = 1e-300  # a tiny non-zero must not be dropped
    assert kf_codegen.structure_key(F2, Q, H, R) != key


@pytest.mark.parametrize("n, m", [(1, 1), (2, 1), (3, 3), (6, 2), (9, 4)])
def test_source_is_valid_python_for_any_shape(n, m):
    rng = np.random.default_rng(n * 10 + m)
    pats = tuple("".join(rng.choice(["0", "1"], size=size)) for size in (n * n, n * n, m * n, m * m))
    source = kf_codegen.linear_kf_source(n, m, pats)
    compile(source, f"<generated n={n} m={m}>", "exec")


def test_source_rejects_empty_dimensions():
    with pytest.raises(ValueError, match="n and m must be >= 1"):
        kf_codegen.linear_kf_source(0, 1, ("", "", "", "1"))


def test_a_change_to_the_inlined_helpers_gives_a_new_module(tmp_path, monkeypatch):
    """numba caches a generated kernel by its own file: the helpers it inlines must be part of the file's name."""
    import hashlib
    from pathlib import Path

    common = Path(kf_codegen.__file__).parent / "common.py"
    assert kf_codegen.depends_digest() == hashlib.sha256(common.read_bytes()).hexdigest()[:16]
    monkeypatch.setenv(generated.ENV_VAR, str(tmp_path))
    pats = ("1111", "0001", "10", "1")
    source = kf_codegen.linear_kf_source(2, 1, pats)
    assert kf_codegen.depends_digest() in source
    before = generated.load_module("linear_kf_n2_m1", source)
    monkeypatch.setattr(kf_codegen, "depends_digest", lambda: "0123456789abcdef")  # common.py edited
    changed = kf_codegen.linear_kf_source(2, 1, pats)
    assert changed != source
    after = generated.load_module("linear_kf_n2_m1", changed)
    assert after.__name__ != before.__name__
    assert len(list(tmp_path.glob("linear_kf_n2_m1_*.py"))) == 2


def test_kernel_dir_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(generated.ENV_VAR, str(tmp_path / "k"))
    assert generated.kernel_dir() == tmp_path / "k"
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv(generated.ENV_VAR, str(blocker / "sub"))
    with pytest.raises(OSError, match=f"{generated.ENV_VAR}=.*cannot create or write"):
        generated.kernel_dir()


def test_load_module_replaces_a_damaged_file(tmp_path, monkeypatch):
    monkeypatch.setenv(generated.ENV_VAR, str(tmp_path))
    source = "VALUE = 42\n"
    first = generated.load_module("probe", source)
    path = next(tmp_path.glob("probe_*.py"))
    path.write_text("VALUE = 1  # damaged\n")
    again = generated.load_module("probe", source)
    assert first.VALUE == again.VALUE == 42
    assert path.read_text() == source


def test_threads_split_the_blocks_and_give_the_same_bits(monkeypatch):
    """run_blocks shares the blocks of runs among threads; each run's bits do not depend on the split."""
    monkeypatch.setattr(particle, "PARALLEL", True)  # the threads, also under make test's PURSUIT_NUMBA_PARALLEL=0
    motion, meas = _models("cv2d-m2")
    zs, prior = _data(motion, meas, M=300, T=6)  # 3 blocks of the sequence kernel, 2 of the step kernel
    filt = pu.KalmanFilter(motion, meas, backend="numba")
    before = numba.get_num_threads()
    try:
        tracks = {}
        for threads in (1, 2):
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
            tracks[threads] = (pu.run(filt, zs, prior, keep_cov=True), pu.run(filt, zs, prior, keep_cov=True, sequence=False))
    finally:
        numba.set_num_threads(before)
    for a, b in zip(tracks[1], tracks[2]):
        assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)
        assert np.array_equal(a.info["loglik"], b.info["loglik"])


def test_run_blocks_covers_every_block_once():
    seen = []

    def kernel(tag, b0, b1):
        seen.extend(range(b0, b1))

    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    generated.run_blocks(kernel, ("t",), runs=1000, block=128, parallel=True)
    assert sorted(seen) == list(range(8))
    seen.clear()
    generated.run_blocks(kernel, ("t",), runs=5, block=128, parallel=True)
    assert seen == [0]
