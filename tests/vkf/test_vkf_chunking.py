"""Chunked processing equals one solve; the stream covers the input once; out-of-core inputs."""

from __future__ import annotations

import math
import warnings

import h5py
import numpy as np
import pytest

from app.analysis.vkf import vkf, vkf_stream
from app.simulate.signals import paper_signal, railway_signal

RTOL = 1e-4  # issue: chunked agrees with unchunked to 1e-4 relative away from the signal ends
BANDWIDTH, Q = 1.5, 2


def _quiet_vkf(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the paper signal's crossing orders warn
        return vkf(*args, **kwargs)


def _quiet_stream(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return list(vkf_stream(*args, **kwargs))


@pytest.fixture(scope="module")
def paper():
    return paper_signal(duration=36.0, fs=4000.0, noise_std=0.75, seed=2)


@pytest.fixture(scope="module")
def unchunked(paper):
    return _quiet_vkf(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=math.inf)


def _assert_close_inside(a: np.ndarray, b: np.ndarray, fs: float, margin_s: float = 1.0) -> None:
    k = int(margin_s * fs)
    err = np.abs(a[..., k:-k] - b[..., k:-k]).max()
    scale = np.abs(b).max()
    assert err <= RTOL * scale, f"max difference {err / scale:.2e} (relative) > {RTOL:.0e}"


@pytest.mark.parametrize("chunk_duration", [5.0, 7.0])
def test_chunked_equals_unchunked(paper, unchunked, chunk_duration):
    res = _quiet_vkf(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=chunk_duration)
    assert res.envelope.shape == unchunked.envelope.shape
    _assert_close_inside(res.envelope, unchunked.envelope, paper.fs)
    _assert_close_inside(res.waveform, unchunked.waveform, paper.fs)
    assert np.all(np.isfinite(res.envelope))


def test_automatic_chunking_equals_unchunked(paper, unchunked):
    res = _quiet_vkf(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q)  # chunk_duration=None
    _assert_close_inside(res.envelope, unchunked.envelope, paper.fs)


@pytest.mark.parametrize(("q", "speed_kmh"), [(2, (40.0, 200.0)), (3, (120.0, 200.0))])
def test_chunked_with_per_sample_bandwidth_and_12_orders(q, speed_kmh):
    """Railway stack, bandwidth 0.1 wheel orders per sample, two channels."""
    sig = railway_signal(duration=30.0, fs=2000.0, speed_kmh=speed_kmh, noise_std=1.0, seed=5)
    sig2 = railway_signal(duration=30.0, fs=2000.0, speed_kmh=speed_kmh, noise_std=1.0, seed=6)
    y = np.vstack([sig.y, sig2.y])
    bandwidth = np.broadcast_to(0.1 * sig.freqs[1], sig.freqs.shape)
    one = _quiet_vkf(y, sig.fs, sig.freqs, bandwidth, q, chunk_duration=math.inf)
    chunked = _quiet_vkf(y, sig.fs, sig.freqs, bandwidth, q, chunk_duration=5.0)
    assert chunked.envelope.shape == (2, 12, sig.n_samples)
    # "away from the ends": 3 s, more than 1/B at the lowest speed (B = 0.38 Hz at 40 km/h)
    _assert_close_inside(chunked.envelope, one.envelope, sig.fs, margin_s=3.0)


def _assert_blocks_cover(blocks, n: int) -> None:
    assert blocks, "vkf_stream yielded nothing"
    assert blocks[0].start == 0
    for prev, nxt in zip(blocks, blocks[1:], strict=False):
        assert nxt.start == prev.stop, "blocks must be contiguous and in order"
    assert blocks[-1].stop == n
    for b in blocks:
        assert b.stop > b.start
        assert b.envelope.shape[-1] == b.stop - b.start
        assert b.waveform.shape[-1] == b.stop - b.start
        assert b.phi.shape[-1] == b.stop - b.start


def _concat(blocks, field: str) -> np.ndarray:
    return np.concatenate([getattr(b, field) for b in blocks], axis=-1)


def test_stream_covers_input_once_and_equals_vkf(paper):
    chunked = _quiet_vkf(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    blocks = _quiet_stream(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    _assert_blocks_cover(blocks, paper.n_samples)
    assert len(blocks) > 1
    scale = np.abs(chunked.envelope).max()
    # a block's phase continues a running sum of f, so phi may differ from the
    # whole-signal cumsum by rounding (~eps·|phi|); the waveform inherits that
    phase_rounding = 64 * np.finfo(float).eps * np.abs(chunked.phi).max()
    for field in ("envelope", "waveform", "phi"):
        got = _concat(blocks, field)
        want = getattr(chunked, field)
        tol = 1e-9 * max(scale, np.abs(want).max())
        if field == "waveform":
            tol += scale * phase_rounding
        assert np.abs(got - want).max() <= tol, field
    np.testing.assert_array_equal(_concat(blocks, "valid"), chunked.valid)


def test_stream_multichannel(paper):
    y = np.vstack([paper.y, -0.5 * paper.y])
    blocks = _quiet_stream(y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=7.0)
    _assert_blocks_cover(blocks, paper.n_samples)
    env = _concat(blocks, "envelope")
    assert env.shape == (2, 3, paper.n_samples)
    scale = np.abs(env).max()
    assert np.abs(env[1] + 0.5 * env[0]).max() <= 1e-9 * scale  # linear in y


def test_memmap_input(paper, tmp_path):
    path = tmp_path / "y.npy"
    np.save(path, paper.y)
    y_mm = np.load(path, mmap_mode="r")
    assert isinstance(y_mm, np.memmap)
    in_memory = _quiet_vkf(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    mapped = _quiet_vkf(y_mm, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    np.testing.assert_allclose(mapped.envelope, in_memory.envelope, rtol=0, atol=1e-12)
    blocks = _quiet_stream(y_mm, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    _assert_blocks_cover(blocks, paper.n_samples)
    np.testing.assert_allclose(_concat(blocks, "envelope"), in_memory.envelope, rtol=0, atol=1e-9)


def test_h5py_dataset_input(paper, tmp_path):
    path = tmp_path / "run.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("z11", data=paper.y, chunks=(40000,))
    in_memory = _quiet_vkf(paper.y, paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    with h5py.File(path, "r") as f:
        blocks = _quiet_stream(f["z11"], paper.fs, paper.freqs, BANDWIDTH, Q, chunk_duration=5.0)
    _assert_blocks_cover(blocks, paper.n_samples)
    np.testing.assert_allclose(_concat(blocks, "envelope"), in_memory.envelope, rtol=0, atol=1e-9)
