"""How much of a support change the 10 m index reads on rough rails: a model of the two-rail estimate.

Per 25 cm bin the two-rail estimate sees ``X = Re((S + R₁) conj(S + R₂))`` (:func:`app.analysis.roughness.two_rail_estimate`):
``S`` the support's sleeper-passage response, ``R₁``, ``R₂`` the two rails' roughness responses in the
order's band, independent circular Gaussian of power ``F = ρ S²`` each, correlated along the track over
``--corr-m`` (a moving average). The rails are fixed to the track, so a change of the support ``S → g S``
meets the same ``R``: what one segment reads of it depends on its own roughness, not on a pass's noise.
Three estimators of a 10 m segment (40 bins) are compared:

* **A** — the store's index: the mean of ``ln √X`` over the positive bins (the correction ``c`` of the
  stored amplitude is a factor that cancels in a change where it is the same before and after);
* **B** — ``ln`` of the mean of ``√max(X, 0)``, the zeros in;
* **C** — ``½ ln`` of the mean of the signed ``X`` (unbiased for ``S²``; NaN where the mean is ≤ 0).

Printed per ``ρ``: the share of bins at 0 (``X ≤ 0``: what the store sees as a zero), the scatter of A
along the line at one support (the rails' own pattern, ``bench_rail_pattern.py`` measures it on the real
line), and per estimator the mean over segments of the change read for ``g`` (truth ``ln g``), its scatter
over segments, and the share of segments without a value; then over a 200 m extent (20 segments, a
tamping's): the median of A's segment changes (the maintenance effect's reader) and C pooled over the
extent's bins, ``½ ln`` of the mean ``X`` (mean and scatter over extents).

Usage::

    .venv/bin/python bench/bench_dilution.py [--g 0.8] [--segments 4000] [--corr-m 4]
"""

from __future__ import annotations

import argparse

import numpy as np

BIN_M = 0.25
SEGMENT_BINS = 40
MIN_POSITIVE = 20  # a segment needs half its bins (the store's rule)
EXTENT_SEGMENTS = 20  # 200 m


def roughness(rng: np.random.Generator, n: int, power: float, corr_bins: int) -> np.ndarray:
    """(n, SEGMENT_BINS) circular Gaussian responses of ``power``, correlated over ``corr_bins`` bins."""
    z = (rng.normal(size=(n, SEGMENT_BINS + corr_bins - 1)) + 1j * rng.normal(size=(n, SEGMENT_BINS + corr_bins - 1)))
    kernel = np.ones(corr_bins) / np.sqrt(corr_bins)
    out = np.empty((n, SEGMENT_BINS), dtype=np.complex128)
    for i in range(n):
        out[i] = np.convolve(z[i], kernel, mode="valid")
    return out * np.sqrt(power / 2.0)


def estimators(x: np.ndarray) -> dict[str, np.ndarray]:
    """Per segment (row of ``x``, the bins' ``X``) the three estimators of ``ln S`` (module docstring)."""
    pos = x > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(pos.sum(axis=1) >= MIN_POSITIVE,
                     np.where(pos, 0.5 * np.log(np.where(pos, x, 1.0)), 0.0).sum(axis=1) / pos.sum(axis=1), np.nan)
        mean_root = np.sqrt(np.maximum(x, 0.0)).mean(axis=1)
        b = np.where(mean_root > 0, np.log(mean_root), np.nan)
        m = x.mean(axis=1)
        c = np.where(m > 0, 0.5 * np.log(np.where(m > 0, m, 1.0)), np.nan)
    return {"A": a, "B": b, "C": c}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--g", type=float, default=0.8, help="the support change's factor on S")
    ap.add_argument("--segments", type=int, default=4000)
    ap.add_argument("--corr-m", type=float, default=4.0)
    ap.add_argument("--rho", type=float, nargs="+", default=[0.1, 0.3, 0.5, 1.0, 1.5, 2.0])
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    if not (0 < args.g and args.segments > 0 and args.corr_m > 0):
        raise SystemExit("--g, --segments and --corr-m must be > 0")
    rng = np.random.default_rng(args.seed)
    corr = max(int(round(args.corr_m / BIN_M)), 1)
    truth = np.log(args.g)
    print(f"support change ln g = {truth:+.3f}; {args.segments} segments of {SEGMENT_BINS} bins; roughness "
          f"correlated over {args.corr_m:g} m")
    print("| ρ = F/S² | bins at 0 | pattern sd of A | A: read (sd over segments, no value) | B | C "
          "| 200 m: median of A | 200 m: C pooled |")
    print("|---|---|---|---|---|---|---|---|")
    per = EXTENT_SEGMENTS
    for rho in args.rho:
        r1 = roughness(rng, args.segments, rho, corr)
        r2 = roughness(rng, args.segments, rho, corr)
        before = np.real((1.0 + r1) * np.conj(1.0 + r2))
        after = np.real((args.g + r1) * np.conj(args.g + r2))
        eb, ea = estimators(before), estimators(after)
        cells = []
        for name in "ABC":
            d = ea[name] - eb[name]
            ok = np.isfinite(d)
            cells.append(f"{np.mean(d[ok]):+.3f} ({np.std(d[ok]):.3f}, {1 - ok.mean():.0%})")
        n_ext = args.segments // per
        da = (ea["A"] - eb["A"])[: n_ext * per].reshape(n_ext, per)
        med = np.nanmedian(da, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            pooled = (0.5 * np.log(after[: n_ext * per].reshape(n_ext, -1).mean(axis=1))
                      - 0.5 * np.log(before[: n_ext * per].reshape(n_ext, -1).mean(axis=1)))
        cells.append(f"{np.nanmean(med):+.3f} ({np.nanstd(med):.3f})")
        cells.append(f"{np.nanmean(pooled):+.3f} ({np.nanstd(pooled):.3f})")
        print(f"| {rho:g} | {np.mean(before <= 0):.1%} | {np.nanstd(eb['A']):.2f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
