"""The Markdown report of a diagnosis and its figures."""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualprobe.diagnose.catalogue import MIN_GAP_CLOSED, SIGNIFICANCE_LEVEL
from dualprobe.diagnose.fit import ModelFit
from dualprobe.diagnose.residuals import WHITENESS_LAGS, moving_mean
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
    for a, fit, title in ((ax[0, 0], base, "baseline"), (ax[1, 0], final, "final")):
        a.plot(t, fit.residual, lw=0.5, color="tab:blue" if fit is base else "tab:orange")
        a.axhline(0.0, color="k", lw=0.5)
        _shade(a, windows)
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
        report.write_text(_markdown(d))
    except OSError as exc:
        raise InputError(f"{report}: cannot write ({exc.strerror or exc})") from None
    return report


def _fmt(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return f"{value:.4g}"
    return str(value)


def _markdown(d: Diagnosis) -> str:
    base, final = d.baseline, d.final
    loc = d.localisation
    lines = [
        "# Discrepancy diagnosis",
        "",
        f"{d.measured.size} samples at {d.sample_interval:g} s "
        f"({d.measured.size * d.sample_interval / 60:.1f} min). White noise estimated from "
        f"second differences: reference {d.noise_std[0]:.3g} K, measured {d.noise_std[1]:.3g} K; "
        f"residual floor of a perfect model (white noise, gas jumps between samples) "
        f"{math.sqrt(d.noise_floor):.3g} K RMS.",
        "",
        "## Result",
        "",
        "Effects found, in order: "
        + (", ".join(f"**{e}**" for e in d.effects) if d.effects else "none")
        + f". Final RMSE {final.rmse:.4g} K against {base.rmse:.4g} K for the baseline; final "
        f"residual {'white' if d.residual_white else 'not white'} "
        f"(Ljung-Box p = {d.tests_final['ljung_box_p']:.3g} over {WHITENESS_LAGS} lags).",
        "",
        "| model | RMSE (K) | fit (%) | gap closed | likelihood ratio (eff.) | delta BIC (eff.) |",
        "|---|---|---|---|---|---|",
        f"| first order (baseline) | {base.rmse:.4g} | {base.fit_percent:.2f} | - | - | - |",
    ]
    for s in d.steps:
        ev = s.evidence
        lines.append(
            f"| + {s.effect} | {s.rmse_after:.4g} | {s.model.fit_percent:.2f} | "
            f"{100 * ev['gap_closed']:.1f} % | {ev['likelihood_ratio']:.4g} | "
            f"{-ev['delta_bic']:.4g} |"
        )
    lines += [
        "",
        "Delta BIC is the change of the information criterion (negative: better), computed with "
        "the effective sample size from the residual autocorrelation.",
        "",
        "![measured vs simulated](fit.png)",
        "",
        "## Baseline",
        "",
        "First order, unity gain: "
        + ", ".join(f"{k} = {v:.4g}" for k, v in base.params.items())
        + f"; RMSE {base.rmse:.4g} K, fit {base.fit_percent:.2f} %.",
        "",
        "## Where the baseline disagrees",
        "",
        "Largest disagreement windows (moving RMS above twice the noise):",
        "",
        "| start (s) | end (s) | RMS (K) | mean (K) | share of squared error | regime |",
        "|---|---|---|---|---|---|",
    ]
    for w in loc["windows"]:
        lines.append(
            f"| {w['start']:.1f} | {w['end']:.1f} | {w['rms']:.3g} | {w['mean']:.3g} | "
            f"{100 * w['share']:.1f} % | {w['regime']} |"
        )
    lines += [
        "",
        "| regime | time share | RMS (K) | mean (K) | share of squared error |",
        "|---|---|---|---|---|",
    ]
    for name, r in loc["regimes"].items():
        lines.append(
            f"| {name} | {100 * r['fraction_of_time']:.1f} % | {r['rms']:.3g} | "
            f"{r['mean']:.3g} | {100 * r['share']:.1f} % |"
        )
    lines += [
        "",
        "Residual power above the white-noise floor, by band relative to the sensor "
        "corner frequency 1/(2 pi tau):",
        "",
    ]
    lines += [f"- {name}: {100 * v:.1f} %" for name, v in loc["frequency"].items()]
    lines += ["", "Physics signatures:", ""]
    lines += [f"- {name}: {_fmt(v)}" for name, v in loc["signatures"].items()]
    tb = d.tests_baseline
    lines += [
        "",
        f"Residual tests (99 % band +-{tb['band']:.3g}): autocorrelation outside the band at "
        f"{100 * tb['autocorrelation_outside_band']:.0f} % of {tb['lags']} lags, "
        f"cross-correlation with the input increments outside at "
        f"{100 * tb['cross_correlation_outside_band']:.0f} % of lags; Ljung-Box p = "
        f"{tb['ljung_box_p']:.3g}.",
        "",
        "![residuals](residual.png)",
        "",
        "![residual correlation](residual_correlation.png)",
        "",
        "![signatures](signatures.png)",
        "",
        "## Steps",
        "",
    ]
    for i, s in enumerate(d.steps, 1):
        lines.append(f"### {i}. {s.effect}")
        lines.append("")
        lines.append("Parameters: " + ", ".join(f"{k} = {v:.5g}" for k, v in s.params.items()))
        lines.append("")
        lines.append(
            f"RMSE {s.rmse_before:.4g} -> {s.rmse_after:.4g} K. Evidence: "
            + ", ".join(
                f"{k} = {_fmt(v)}" for k, v in s.evidence.items() if not isinstance(v, Mapping)
            )
            + "."
        )
        lines += [
            "",
            "| candidate | RMSE (K) | gap closed | likelihood ratio | size / minimum "
            "| significant |",
            "|---|---|---|---|---|---|",
        ]
        for name, c in s.candidates.items():
            lines.append(
                f"| {name} | {c['rmse']:.4g} | {100 * c['gap_closed']:.1f} % | "
                f"{c['likelihood_ratio']:.4g} | {c['effect_size_over_minimum']:.3g} | "
                f"{_fmt(c['significant'])} |"
            )
        lines.append("")
    if d.last_round:
        lines += [
            "### Last round: nothing significant remains",
            "",
            "| candidate | RMSE (K) | gap closed | likelihood ratio | size / minimum |",
            "|---|---|---|---|---|",
        ]
        for name, c in d.last_round.items():
            lines.append(
                f"| {name} | {c['rmse']:.4g} | {100 * c['gap_closed']:.1f} % | "
                f"{c['likelihood_ratio']:.4g} | {c['effect_size_over_minimum']:.3g} |"
            )
        lines.append("")
    if d.dropped:
        lines += [f"Dropped as redundant given the others: {', '.join(d.dropped)}.", ""]
    lines += [
        "## Method",
        "",
        "Each candidate extends the current model by one catalogued effect and is fitted by "
        "nonlinear least squares (exact discretisation, reference linearly interpolated). It is "
        f"accepted when the likelihood ratio with the effective sample size passes chi-square at "
        f"{SIGNIFICANCE_LEVEL:g} and BIC, it closes at least {100 * MIN_GAP_CLOSED:.0f} % of the "
        "remaining gap above the noise floor, and the effect is at least a quarter of a "
        "realistic size; a simpler candidate that does nearly as well is preferred.",
        "",
    ]
    return "\n".join(lines)
