"""Bad input is refused with a ValueError naming the argument; odd-but-legal input is handled."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from app.analysis.orders import sleeper_passage, wheel_orders
from app.analysis.vkf import VKFWarning, vkf, vkf_stream
from app.simulate.signals import railway_signal

FS = 1000.0
N = 2000


def _good() -> dict:
    t = np.arange(N) / FS
    freqs = np.vstack([100 + 10 * t, np.full(N, 250.0)])
    y = np.cos(2 * np.pi * 100 * t) + 0.1 * np.sin(2 * np.pi * 250 * t)
    return {"y": y, "fs": FS, "freqs": freqs, "bandwidth": 5.0, "filter_order": 2}


def _with(**changes) -> dict:
    args = _good()
    args.update(changes)
    return args


def _nan_at(a: np.ndarray, index) -> np.ndarray:
    a = np.array(a, dtype=float)
    a[index] = np.nan
    return a


def _inf_at(a: np.ndarray, index) -> np.ndarray:
    a = np.array(a, dtype=float)
    a[index] = np.inf
    return a


G = _good()
BAD_INPUTS = {
    # y
    "y-nan": (_with(y=_nan_at(G["y"], 10)), "y"),
    "y-inf": (_with(y=_inf_at(G["y"], -1)), "y"),
    "y-empty": (_with(y=np.zeros(0), freqs=np.array([100.0, 250.0])), "y"),
    "y-3d": (_with(y=np.zeros((2, 2, N))), "y"),
    "y-channel-nan": (_with(y=_nan_at(np.vstack([G["y"], G["y"]]), (1, 5))), "y"),
    # fs
    "fs-zero": (_with(fs=0.0), "fs"),
    "fs-negative": (_with(fs=-1000.0), "fs"),
    "fs-nan": (_with(fs=float("nan")), "fs"),
    "fs-inf": (_with(fs=float("inf")), "fs"),
    # freqs
    "freqs-length": (_with(freqs=G["freqs"][:, :-1]), "freqs"),
    "freqs-3d": (_with(freqs=G["freqs"][None]), "freqs"),
    "freqs-nan": (_with(freqs=_nan_at(G["freqs"], (0, 7))), "freqs"),
    "freqs-inf": (_with(freqs=_inf_at(G["freqs"], (1, 7))), "freqs"),
    "freqs-negative": (_with(freqs=np.vstack([G["freqs"][0] - 120.0, G["freqs"][1]])), "freqs"),
    "freqs-nyquist": (_with(freqs=np.vstack([G["freqs"][0], np.full(N, 500.0)])), "freqs"),
    "freqs-above-nyquist": (_with(freqs=np.array([100.0, 600.0])), "freqs"),
    "freqs-empty": (_with(freqs=np.zeros((0, N))), "freqs"),
    # bandwidth
    "bandwidth-zero": (_with(bandwidth=0.0), "bandwidth"),
    "bandwidth-negative": (_with(bandwidth=np.array([5.0, -1.0])), "bandwidth"),
    "bandwidth-nan": (_with(bandwidth=float("nan")), "bandwidth"),
    "bandwidth-inf": (_with(bandwidth=np.array([5.0, np.inf])), "bandwidth"),
    "bandwidth-zero-somewhere": (
        _with(bandwidth=np.where(np.arange(N) == 99, 0.0, 5.0) * np.ones((2, 1))),
        "bandwidth",
    ),
    "bandwidth-orders": (_with(bandwidth=np.array([5.0, 5.0, 5.0])), "bandwidth"),
    "bandwidth-length": (_with(bandwidth=np.full((2, N - 1), 5.0)), "bandwidth"),
    # filter_order
    "filter_order-0": (_with(filter_order=0), "filter_order"),
    "filter_order-4": (_with(filter_order=4), "filter_order"),
    "filter_order-negative": (_with(filter_order=-2), "filter_order"),
    "filter_order-fraction": (_with(filter_order=1.5), "filter_order"),
}


def _names(message: str, word: str) -> bool:
    return re.search(rf"(?<![A-Za-z_]){re.escape(word)}(?![A-Za-z_])", message) is not None


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_raises_value_error_naming_the_argument(case):
    args, word = BAD_INPUTS[case]
    with pytest.raises(ValueError) as info:
        vkf(**args)
    assert _names(str(info.value), word), f"message does not name {word!r}: {info.value}"


def test_bad_channel_is_named():
    """House rule: errors name the offending channel of a (channels, N) y."""
    y = np.vstack([G["y"], G["y"], _nan_at(G["y"], 5)])
    with pytest.raises(ValueError) as info:
        vkf(**_with(y=y))
    message = str(info.value)
    assert _names(message, "y") and re.search(r"channel\D{0,3}2", message), message


@pytest.mark.parametrize(
    "case", ["y-nan", "fs-zero", "freqs-length", "bandwidth-zero", "filter_order-4"]
)
def test_stream_refuses_bad_input_too(case):
    args, word = BAD_INPUTS[case]
    with pytest.raises(ValueError) as info:
        list(vkf_stream(**args))
    assert _names(str(info.value), word), f"message does not name {word!r}: {info.value}"


# house rule (validate up front, name the argument): the keyword options as well
OPTION_CASES = {
    "phase0-shape": ({"phase0": np.zeros(3)}, "phase0"),
    "phase0-nan": ({"phase0": np.array([0.0, np.nan])}, "phase0"),
    "decimation-word": ({"decimation": "fast"}, "decimation"),
    "decimation-zero": ({"decimation": 0}, "decimation"),
    "chunk_duration-zero": ({"chunk_duration": 0.0}, "chunk_duration"),
    "chunk_duration-negative": ({"chunk_duration": -5.0}, "chunk_duration"),
    "chunk_duration-nan": ({"chunk_duration": float("nan")}, "chunk_duration"),
}


@pytest.mark.parametrize("case", sorted(OPTION_CASES))
def test_bad_options_raise_value_error_naming_the_option(case):
    options, word = OPTION_CASES[case]
    with pytest.raises(ValueError) as info:
        vkf(**_good(), **options)
    assert _names(str(info.value), word), f"message does not name {word!r}: {info.value}"


def test_good_input_passes_in_every_accepted_form():
    args = _good()
    res = vkf(**args)
    assert res.envelope.shape == (2, N)
    # list input, integer y, (s,) freqs, (s,) bandwidth, a single order as (1, N)
    res_list = vkf(list(args["y"]), FS, args["freqs"].tolist(), [5.0, 5.0], 2)
    np.testing.assert_allclose(res_list.envelope, res.envelope, atol=1e-12)
    vkf(np.round(100 * args["y"]).astype(np.int16), FS, [100.0, 250.0], 5.0, 1)
    one = vkf(args["y"], FS, np.full((1, N), 100.0), 5.0, 3)
    assert one.envelope.shape[-2:] == (1, N)
    # 0 Hz is a legal frequency (a standing train), as is a float32 y
    vkf(args["y"].astype(np.float32), FS, np.array([0.0, 250.0]), 5.0, 2)


# ---------------------------------------------------------------- standing train


def test_standing_train_gives_nan_and_invalid_not_a_crash():
    fs = 2000.0
    duration = 20.0
    n = int(duration * fs)
    t = np.arange(n) / fs
    # 60 km/h, brake to a stop at 10 s, stand 4 s, start again and reach 60 km/h at 16 s
    brake = np.clip((10.0 - t) / 2.0, 0.0, 1.0)
    go = np.clip((t - 14.0) / 2.0, 0.0, 1.0)
    speed_kmh = 60.0 * np.where(t < 12.0, brake, go)
    sig = railway_signal(duration=duration, fs=fs, speed_kmh=speed_kmh, noise_std=0.5, seed=2)
    bandwidth = 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)  # at standstill all orders meet at 0 Hz
        res = vkf(sig.y, fs, sig.freqs, bandwidth, 2)
    below = sig.freqs < bandwidth
    above = sig.freqs > bandwidth
    assert below.any() and above.any()
    assert not res.valid[below].any(), "orders below their bandwidth must be flagged invalid"
    assert res.valid[above].all(), "orders above their bandwidth must be valid"
    assert np.all(np.isnan(res.amplitude[~res.valid]))
    assert np.all(np.isnan(res.envelope[~res.valid]))
    assert np.all(np.isfinite(res.amplitude[res.valid]))
    # while running at 60 km/h (well away from the stop) the sleeper order is still right
    steady = (t > 2.0) & (t < 7.0)
    err = np.abs(res.amplitude[0, steady] - sig.amplitude[0, steady]).max()
    assert err <= 0.1 * sig.amplitude[0, steady].max()


def test_train_standing_from_the_start():
    """A whole record at 0 km/h: no crash, everything invalid."""
    n = 4000
    speed = np.zeros(n)
    freqs = np.vstack([sleeper_passage(speed, 0.6), wheel_orders(speed, 0.92, 11)])
    y = np.random.default_rng(0).standard_normal(n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", VKFWarning)
        res = vkf(y, 2000.0, freqs, 1.0, 2)
    assert not res.valid.any()
    assert np.all(np.isnan(res.amplitude))


# ---------------------------------------------------------------- close and crossing orders


def test_crossing_orders_are_reported_and_warned():
    fs, n = 1000.0, 3000
    t = np.arange(n) / fs
    freqs = np.vstack([100 + 20 * t, 160 - 20 * t, np.full(n, 350.0)])  # 0 and 1 cross at 1.5 s
    y = np.cos(2 * np.pi * np.cumsum(freqs[0]) / fs) + np.cos(2 * np.pi * np.cumsum(freqs[1]) / fs)
    with pytest.warns(VKFWarning):
        res = vkf(y, fs, freqs, 2.0, 2)
    assert {tuple(sorted(p)) for p in res.close_orders} == {(0, 1)}


@pytest.mark.parametrize(("orders_bw", "expected"), [(0.1, set()), (0.2, {(0, 5)})])
def test_sleeper_and_wheel_order_5(orders_bw, expected):
    """The sleeper order sits 0.18 orders from wheel order 5: close only for a wider band."""
    sig = railway_signal(duration=10.0, fs=1000.0, speed_kmh=(80.0, 160.0), noise_std=0.5)
    bandwidth = np.broadcast_to(orders_bw * sig.freqs[1], sig.freqs.shape)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = vkf(sig.y, sig.fs, sig.freqs, bandwidth, 2)
    assert {tuple(sorted(p)) for p in res.close_orders} == expected
    vkf_warnings = [w for w in caught if issubclass(w.category, VKFWarning)]
    assert bool(vkf_warnings) == bool(expected)
