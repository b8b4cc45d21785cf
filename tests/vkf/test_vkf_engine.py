"""Core checks of the VKF engine against ground truth and direct sparse solves of Eq. 20 and its real-signal form."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from app.analysis.orders import OrderTrack, railway_multipliers, sleeper_passage, wheel_orders
from app.analysis.vkf import CLOSE_ORDERS_MESSAGE, VKFWarning, vkf, vkf_stream


def r_from_bandwidth(bw: float, fs: float, q: int) -> float:
    return math.sqrt(math.sqrt(2.0) - 1.0) / (2.0 * math.sin(math.pi * bw / (2.0 * fs))) ** q


def _carriers_and_differences(fs: float, f: np.ndarray, q: int) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """C (carriers of the orders, N x sN) and S (q-th differences of every order, s(N-q) x sN)."""
    s, n = f.shape
    phi = 2.0 * np.pi * np.cumsum(f, axis=1) / fs
    c = sp.hstack([sp.diags(np.exp(1j * p)) for p in phi]).tocsc()
    d = sp.eye(n, format="csr")
    for _ in range(q):
        d = d[1:] - d[:-1]
    return c, sp.kron(sp.eye(s), d).tocsc()


def sparse_eq20(y: np.ndarray, fs: float, f: np.ndarray, r: float, q: int) -> np.ndarray:
    """Eq. 20 assembled as written and solved directly; returns the paper's A (s, N)."""
    s, n = f.shape
    c, big_s = _carriers_and_differences(fs, f, q)
    m = (c.conj().T @ c + (r * big_s).T @ (r * big_s)).tocsc()
    return spl.spsolve(m, c.conj().T @ y.astype(complex)).reshape(s, n)


def sparse_real_model(y: np.ndarray, fs: float, f: np.ndarray, bw: np.ndarray, q: int) -> np.ndarray:
    """The real-signal form of Eq. 20, solved directly; returns the engine's envelopes (s, N).

    Minimises ``Σ (y − Re(Σ_n e_n·exp(jφ_n)))² + Σ_n r_n² |S_q e_n|² / 2`` over the
    envelopes ``e_n = 2 A_n``: normal equations ``(CᴴC + R) A + Cᴴ conj(C A) = Cᴴ y``,
    written for the real and imaginary parts of A.
    """
    s, n = f.shape
    c, big_s = _carriers_and_differences(fs, f, q)
    rs = sp.diags(np.repeat([r_from_bandwidth(b, fs, q) for b in bw], n - q)) @ big_s
    a_mat = (c.conj().T @ c + rs.T @ rs).tocsc()
    b_mat = (c.conj().T @ c.conj()).tocsc()
    rhs = c.conj().T @ y.astype(complex)
    big = sp.bmat([[(a_mat + b_mat).real, -(a_mat - b_mat).imag], [(a_mat + b_mat).imag, (a_mat - b_mat).real]])
    u = spl.spsolve(big.tocsc(), np.concatenate([rhs.real, rhs.imag]))
    return 2.0 * (u[: s * n] + 1j * u[s * n :]).reshape(s, n)


@pytest.mark.parametrize("q", [1, 2])
def test_real_signal_model_matches_direct_solve(q: int) -> None:
    """A wide order beside narrow ones: the engine solves the real-signal model exactly.

    (q = 3 at these full-rate weights is beyond what the direct sparse solve resolves.)
    """
    fs, n = 1000.0, 3000
    f = np.array([58.3, 60.5, 48.4, 175.0])[:, None] * np.ones(n)
    bw = np.array([10.5, 3.0, 3.0, 10.5])
    t = np.arange(n) / fs
    y = np.cos(2 * np.pi * 58.3 * t) + 0.5 * np.cos(2 * np.pi * 60.5 * t + 1.0)
    y = y + np.random.default_rng(q).normal(0.0, 0.3, n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)
        res = vkf(y, fs, f, bw, q, decimation="off", chunk_duration=math.inf)
        eq20 = vkf(y, fs, f, bw, q, decimation="off", chunk_duration=math.inf, real_signal=False)
    ref = sparse_real_model(y, fs, f, bw, q)
    assert np.abs(res.envelope - ref).max() <= 1e-5 * np.abs(ref).max()
    assert np.abs(eq20.envelope - ref).max() > 1e-3 * np.abs(ref).max()  # the images matter here


@pytest.mark.parametrize("decimation", ["auto", "off"])
def test_wide_order_beside_narrow_ones_is_exact_to_the_ends(decimation: str) -> None:
    """A real tone tracked by a wide order next to narrow ones comes back exact, ends included.

    At 5 kHz (every order below 140 Hz, far under Nyquist): the full-rate solve's cost grows faster
    than the samples, and at 10 kHz the same errors came back (real 3e-10, Eq. 20 0.021) in 8x the time."""
    fs, v = 5_000.0, 35.0
    n = int(3 * fs)
    x = np.arange(n) * v / fs
    f = np.concatenate([[v / 0.6], np.arange(1, 12) * v / (np.pi * 0.92)])
    bw = np.concatenate([[10.5], np.full(11, 1.2)])
    y = np.cos(2 * np.pi * x / 0.6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)
        real = vkf(y, fs, f, bw, 2, decimation=decimation)
        eq20 = vkf(y, fs, f, bw, 2, decimation=decimation, real_signal=False)
    assert np.abs(real.amplitude[0] - 1.0).max() < 1e-3
    assert np.abs(eq20.amplitude[0] - 1.0).max() > 1e-2  # Eq. 20 as written leaves the images in


@pytest.mark.parametrize("q", [1, 2, 3])
@pytest.mark.parametrize("s", [1, 3, 12])
def test_matches_direct_sparse_solve(q: int, s: int) -> None:
    fs, n = 1000.0, 3000
    t = np.arange(n) / fs
    f = np.linspace(80.0, 420.0, s)[:, None] + 15.0 * np.sin(2 * np.pi * 0.7 * t)[None, :]
    if s >= 3:
        f[1] = f[0] + 30.0  # a close pair: 1.5 bandwidths apart
    rng = np.random.default_rng(q * 10 + s)
    y = np.cos(2 * np.pi * np.cumsum(f[0]) / fs) + rng.normal(0.0, 0.5, n)
    bw = 20.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)
        res = vkf(y, fs, f, bw, q, decimation="off", chunk_duration=math.inf, real_signal=False)
    ref = 2.0 * sparse_eq20(y, fs, f, r_from_bandwidth(bw, fs, q), q)
    assert np.abs(res.envelope - ref).max() <= 1e-6 * np.abs(ref).max()


@pytest.mark.parametrize("q", [1, 2, 3])
def test_unit_tone_at_paper_settings(q: int) -> None:
    fs = 12000.0
    t = np.arange(int(20 * fs)) / fs
    res = vkf(np.cos(2 * np.pi * 500.0 * t), fs, [500.0], 1.5, q)
    interior = res.amplitude[0, int(6 * fs) : int(14 * fs)]
    assert np.all(np.abs(interior - 1.0) <= 1e-3)


def test_unit_tone_full_rate_is_unbiased() -> None:
    """r² ≈ 1.7e13: refinement removes the rounding bias of a plain solve."""
    fs = 12000.0
    t = np.arange(int(8 * fs)) / fs
    res = vkf(np.cos(2 * np.pi * 500.0 * t), fs, [500.0], 1.5, 2, decimation="off")
    assert abs(res.amplitude[0, int(4 * fs)] - 1.0) <= 1e-6


def test_q3_narrow_band_high_rate() -> None:
    fs = 24000.0
    t = np.arange(int(60 * fs)) / fs
    res = vkf(0.7 * np.cos(2 * np.pi * 100.0 * t + 1.0), fs, [100.0], 0.5, 3)
    mid = slice(int(25 * fs), int(35 * fs), 97)
    assert np.all(np.abs(res.amplitude[0, mid] - 0.7) <= 1e-3)


def _paper_signal(fs: float = 12000.0, duration: float = 60.0, seed: int = 1):
    n = int(duration * fs)
    t = np.arange(n) / fs
    a = np.vstack([0.02 * t + 1, 1 + 0.5 * np.sin(2 * np.pi * 0.02 * t) * np.cos(2 * np.pi * 0.04 * t), np.ones(n)])
    f = np.vstack([600 + 120 * np.cos(2 * np.pi * 0.03 * t), 240 - 120 * np.cos(2 * np.pi * 0.01 * t), np.full(n, 500.0)])
    p = np.vstack([0.06 * t - 2, 0 * t, -np.ones(n)])
    x = a * np.cos(2 * np.pi * np.cumsum(f, axis=1) / fs + p)
    y = x.sum(axis=0) + np.random.default_rng(seed).normal(0.0, 0.75, n)
    return y, f, x


def test_paper_signal_waveforms_within_2_percent() -> None:
    fs = 12000.0
    y, f, x = _paper_signal(fs)
    with pytest.warns(VKFWarning, match="closer than their bandwidth"):
        res = vkf(y, fs, f, 1.5, 2)
    assert (0, 2) in res.close_orders  # order 1 crosses the 500 Hz order
    m = slice(int(fs), y.size - int(fs))
    for i in range(3):
        err = np.sqrt(np.mean((res.waveform[i, m] - x[i, m]) ** 2) / np.mean(x[i, m] ** 2))
        assert err <= 0.02, (i, err)


def test_chunked_equals_unchunked_and_stream_covers_once() -> None:
    fs = 4000.0
    y, f, _ = _paper_signal(fs, 40.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)
        whole = vkf(y, fs, f, 3.0, 2, chunk_duration=math.inf)
        chunked = vkf(y, fs, f, 3.0, 2, chunk_duration=6.0)
        blocks = list(vkf_stream(y, fs, f, 3.0, 2, chunk_duration=6.0))
    assert len(chunked.info["chunks"]) > 3
    m = slice(int(2 * fs), y.size - int(2 * fs))
    scale = np.abs(whole.envelope[:, m]).max()
    assert np.abs(chunked.envelope[:, m] - whole.envelope[:, m]).max() <= 1e-4 * scale
    assert blocks[0].start == 0 and blocks[-1].stop == y.size
    assert all(a.stop == b.start for a, b in zip(blocks, blocks[1:], strict=False))
    joined = np.concatenate([b.envelope for b in blocks], axis=1)
    np.testing.assert_allclose(joined, chunked.envelope, rtol=0, atol=1e-12 * scale)


def test_stream_reduced_rate_and_multichannel() -> None:
    """The bounded-memory recipe of docs/vkf.md: every step-th amplitude, block by block."""
    fs = 4000.0
    y, f, _ = _paper_signal(fs, 20.0)
    y2 = np.vstack([y, 2.0 * y])
    step = 8
    out = np.zeros((2, 3, -(-y.size // step)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)
        for block in vkf_stream(y2, fs, f, 3.0, 2, chunk_duration=6.0):
            k = np.arange(-(-block.start // step) * step, block.stop, step)
            out[..., k // step] = np.abs(block.envelope_at(k - block.start))
        single = vkf(y, fs, f, 3.0, 2, chunk_duration=6.0)
    np.testing.assert_allclose(out[0], single.amplitude[:, ::step], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out[1], 2.0 * single.amplitude[:, ::step], rtol=1e-9, atol=1e-12)


def test_railway_sleeper_order_recovered() -> None:
    fs, duration = 10000.0, 40.0
    n = int(fs * duration)
    t = np.arange(n) / fs
    v = (40.0 + 160.0 * 0.5 * (1 - np.cos(2 * np.pi * t / duration))) / 3.6
    mult = railway_multipliers(0.92, 0.6, 11)
    phi = 2 * np.pi * np.outer(mult, np.cumsum(v)) / fs
    amp = np.vstack([1.0 + 0.4 * np.sin(2 * np.pi * t / 13.0)] + [np.full(n, 0.6)] * 11)
    y = (amp * np.cos(phi)).sum(axis=0) + np.random.default_rng(3).normal(0.0, 2.0, n)
    bw = OrderTrack(v, np.full(12, 0.1 / (np.pi * 0.92)))
    res = vkf(y, fs, OrderTrack(v, mult), bw, 2)
    idx = np.arange(int(3 * fs), n - int(3 * fs), 10)
    a = np.abs(res.envelope_at(idx)[0])
    err = np.sqrt(np.mean((a - amp[0, idx]) ** 2) / np.mean(amp[0, idx] ** 2))
    assert err <= 0.05
    np.testing.assert_allclose(np.vstack([sleeper_passage(v[:5]), wheel_orders(v[:5])]), np.outer(mult, v[:5]))


def test_standing_train_gives_nan_not_crash() -> None:
    fs = 2000.0
    n = 40000
    v = np.full(n, 20.0)
    v[15000:25000] = 0.0
    mult = railway_multipliers(0.92, 0.6, 3)
    y = np.cos(2 * np.pi * np.cumsum(mult[0] * v) / fs)
    with pytest.warns(VKFWarning, match=CLOSE_ORDERS_MESSAGE):  # at standstill all orders meet at 0 Hz
        res = vkf(y, fs, OrderTrack(v, mult), OrderTrack(v, np.full(4, 0.035), floor=0.1), 2)
    assert not res.valid[0, 20000] and np.isnan(res.amplitude[0, 20000])
    assert res.valid[0, 5000] and abs(res.amplitude[0, 5000] - 1.0) < 0.02


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"y": np.array([1.0, np.nan] * 50)}, "y"),
        ({"y": np.zeros(0)}, "y"),
        ({"y": np.zeros((2, 3, 100))}, "y"),
        ({"freqs": np.full((1, 99), 10.0)}, "freqs"),
        ({"freqs": [600.0]}, "freqs"),
        ({"freqs": [-1.0]}, "freqs"),
        ({"freqs": [np.inf]}, "freqs"),
        ({"bandwidth": 0.0}, "bandwidth"),
        ({"bandwidth": [1.0, 2.0]}, "bandwidth"),
        ({"filter_order": 4}, "filter_order"),
        ({"filter_order": 2.0}, "filter_order"),
        ({"fs": -5.0}, "fs"),
    ],
)
def test_bad_input_names_the_argument(kwargs: dict, name: str) -> None:
    args = {"y": np.ones(100), "fs": 1000.0, "freqs": [10.0], "bandwidth": 1.0, "filter_order": 2}
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        vkf(args.pop("y"), **args)


@pytest.mark.parametrize("q", [1, 2, 3])
def test_unit_tone_exact_to_the_very_ends(q):
    """Decimated solve: no edge transient (FIR edge samples leave the data equation)."""
    fs = 12_000.0
    t = np.arange(int(20 * fs)) / fs
    res = vkf(np.cos(2 * np.pi * 50.0 * t + 0.3), fs, [50.0], 1.5, q)
    assert res.info["chunks"][0]["decimation"] > 1
    np.testing.assert_allclose(res.amplitude[0], 1.0, atol=1e-5)


def test_one_dimensional_per_sample_freqs_are_refused_with_a_hint():
    fs, n = 1000.0, 5000
    y = np.zeros(n)
    with pytest.raises(ValueError, match=r"freqs has shape \(5000,\).*\(1, N\)"):
        vkf(y, fs, np.full(n, 50.0), 2.0)
