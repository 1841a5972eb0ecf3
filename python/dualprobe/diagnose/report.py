"""The Markdown report of a diagnosis and its figures."""

from __future__ import annotations

import itertools
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualprobe.diagnose.fit import ModelFit
from dualprobe.diagnose.markdown import markdown
from dualprobe.diagnose.residuals import moving_mean
from dualprobe.io import InputError
from dualprobe.report.plots import figure

if TYPE_CHECKING:
    from dualprobe.diagnose.result import Diagnosis

__all__ = [
    "FIGURES",
    "REPORT_NAME",
    "write_report",
]


REPORT_NAME = "report.md"
FIGURES = {
    "fit": "fit.png",
    "residual": "residual.png",
    "correlation": "residual_correlation.png",
    "signatures": "signatures.png",
}


def _rate_classes(measured: np.ndarray, ts: float) -> np.ndarray:
    """-1 falling, 0 steady, +1 rising: sign of the smoothed rate of change of the measured
    output, with a dead band of 5 robust standard deviations of that rate (steady most of the
    time, so the median absolute deviation is the noise of the rate)."""
    width = max(3, round(1.0 / ts))
    rate = np.gradient(moving_mean(measured, width), ts)
    spread = 1.482602218505602 * float(np.median(np.abs(rate - np.median(rate))))
    band = max(5.0 * spread, 1e-12)
    return np.where(rate > band, 1, np.where(rate < -band, -1, 0))


def _shade(ax: Any, windows: Sequence[Mapping[str, Any]]) -> None:
    for w in windows:
        ax.axvspan(w["start"], w["end"], color="tab:red", alpha=0.15, lw=0)


def _model_label(fit: ModelFit) -> str:
    return "first order" + "".join(f" + {e}" for e in fit.effects)


def write_report(diagnosis: Diagnosis, directory: str | os.PathLike[str]) -> Path:
    """Markdown report and the figures of the issue in `directory` (created if needed)."""
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create directory ({exc.strerror or exc})") from None
    d = diagnosis
    t = d.time
    base, final = d.baseline, d.final
    windows = d.localisation["windows"]

    fig, ax = figure(11, 5)
    a = ax[0, 0]
    a.plot(t, d.reference, color="0.75", lw=0.6, label="reference (input)")
    a.plot(t, d.measured, color="k", lw=0.8, label="measured")
    a.plot(t, base.prediction, color="tab:blue", lw=0.9, label="baseline: first order")
    if d.steps:
        a.plot(
            t,
            final.prediction,
            color="tab:orange",
            lw=0.9,
            ls="--",
            label=f"final: {_model_label(final)}",
        )
    _shade(a, windows)
    a.set_xlabel("time (s)")
    a.set_ylabel("temperature (degC)")
    a.set_title("measured vs simulated (shaded: largest disagreement of the baseline)")
    a.legend(loc="best", fontsize=8)
    fig.savefig(out / FIGURES["fit"], dpi=110)

    fig, ax = figure(11, 6, rows=2)
    limit = float(np.max(np.abs(base.residual))) * 1.05 or 1.0
    shading = (
        (ax[0, 0], base, "baseline", windows),
        (ax[1, 0], final, "final", d.misfit.get("windows", [])),
    )
    for a, fit, title, spans in shading:
        a.plot(t, fit.residual, lw=0.5, color="tab:blue" if fit is base else "tab:orange")
        a.axhline(0.0, color="k", lw=0.5)
        _shade(a, spans)
        a.set_ylim(-limit, limit)
        a.set_ylabel("residual (K)")
        a.set_title(f"{title}: {_model_label(fit)}, RMSE {fit.rmse:.3g} K")
    ax[1, 0].set_xlabel("time (s)")
    fig.savefig(out / FIGURES["residual"], dpi=110)

    fig, ax = figure(11, 6, rows=2, cols=2)
    for col, (tests, title) in enumerate(
        ((d.tests_baseline, "baseline"), (d.tests_final, "final"))
    ):
        lags = np.arange(tests["autocorrelation"].size)
        a = ax[0, col]
        a.vlines(lags * d.sample_interval, 0, tests["autocorrelation"], lw=0.8)
        a.axhspan(-tests["band"], tests["band"], color="tab:green", alpha=0.2)
        a.set_title(f"{title}: residual autocorrelation (99 % band)")
        a.set_xlabel("lag (s)")
        cross = tests["cross_correlation"]
        m = (cross.size - 1) // 2
        a = ax[1, col]
        a.vlines(np.arange(-m, m + 1) * d.sample_interval, 0, cross, lw=0.8)
        a.axhspan(-tests["band"], tests["band"], color="tab:green", alpha=0.2)
        a.set_title(f"{title}: cross-correlation with input increments")
        a.set_xlabel("lag (s)")
    fig.savefig(out / FIGURES["correlation"], dpi=110)

    classes = _rate_classes(d.measured, d.sample_interval)
    fig, ax = figure(11, 6, rows=2, cols=2)
    for col, (fit, title) in enumerate(((base, "baseline"), (final, "final"))):
        a = ax[0, col]
        data = [fit.residual[classes == c] for c in (-1, 0, 1)]
        labels = ["falling", "steady", "rising"]
        kept = [(x, lab) for x, lab in zip(data, labels, strict=True) if x.size]
        a.boxplot([x for x, _ in kept], showfliers=False)
        a.set_xticks(range(1, len(kept) + 1), [lab for _, lab in kept])
        a.axhline(0.0, color="k", lw=0.5)
        a.set_title(f"{title}: residual vs sign of the rate of change")
        a.set_ylabel("residual (K)")
        a = ax[1, col]
        step = max(1, d.measured.size // 5000)
        a.plot(d.measured[::step], fit.residual[::step], ".", ms=1, alpha=0.4)
        edges = np.quantile(d.measured, np.linspace(0, 1, 21))
        centres, means = [], []
        for lo, hi in itertools.pairwise(edges):
            mask = (d.measured >= lo) & (d.measured <= hi) & (classes == 0)
            if np.sum(mask) > 10:
                centres.append(0.5 * (lo + hi))
                means.append(float(np.mean(fit.residual[mask])))
        a.plot(centres, means, "o-", color="tab:red", ms=3, label="steady-state mean")
        a.axhline(0.0, color="k", lw=0.5)
        a.set_xlabel("measured level (degC)")
        a.set_ylabel("residual (K)")
        a.set_title(f"{title}: residual vs level")
        a.legend(loc="best", fontsize=8)
    fig.savefig(out / FIGURES["signatures"], dpi=110)

    report = out / REPORT_NAME
    try:
        report.write_text(markdown(d))
    except OSError as exc:
        raise InputError(f"{report}: cannot write ({exc.strerror or exc})") from None
    return report
