"""The text of the Markdown report: the verdict, the ladder, where the baseline disagrees and
where the remaining misfit lives. One sign convention for delta BIC everywhere: > 0 is
evidence for the effect. Every parameter with its unit."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from dualprobe.diagnose.catalogue import UNITS
from dualprobe.diagnose.evidence import MIN_GAP_CLOSED, SIGNIFICANCE_LEVEL
from dualprobe.diagnose.residuals import WHITENESS_LAGS
from dualprobe.diagnose.verdict import MISFIT_LIMIT, STRUCTURE_P

if TYPE_CHECKING:
    from dualprobe.diagnose.result import Diagnosis

__all__ = ["markdown"]


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return f"{value:.4g}"
    return str(value)


def _param(name: str, value: float) -> str:
    unit = UNITS.get(name, "")
    return f"{name} = {value:.5g}" + (f" {unit}" if unit not in ("", "1") else "")


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f} %"


def _regimes(regimes: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> list[str]:
    """One table per group of regimes; each group partitions the record (time shares and
    shares of the squared error add up to 100 %)."""
    titles = {
        "direction": "direction of heat flow",
        "level": "level band (thirds of the reference's range, degC)",
        "flow": "flow band (thirds of the flow's range)",
    }
    lines: list[str] = []
    for group, table in regimes.items():
        lines += [
            "",
            f"| {titles.get(group, group)} | range | time share | RMS (K) | mean (K) "
            "| share of squared error |",
            "|---|---|---|---|---|---|",
        ]
        for name, r in table.items():
            span = "-" if "range" not in r else f"{r['range'][0]:.4g} - {r['range'][1]:.4g}"
            lines.append(
                f"| {name} | {span} | {100 * r['fraction_of_time']:.1f} % | {r['rms']:.3g} | "
                f"{r['mean']:.3g} | {100 * r['share_of_squared_error']:.1f} % |"
            )
    return lines


def _windows(windows: list[Mapping[str, Any]]) -> list[str]:
    if not windows:
        return ["", "No window stands out (moving RMS nowhere above twice the noise)."]
    lines = [
        "",
        "| start (s) | end (s) | RMS (K) | mean (K) | share of squared error | regime |",
        "|---|---|---|---|---|---|",
    ]
    for w in windows:
        lines.append(
            f"| {w['start']:.1f} | {w['end']:.1f} | {w['rms']:.3g} | {w['mean']:.3g} | "
            f"{100 * w['share']:.1f} % | {w['regime']} |"
        )
    return lines


def _frequency(frequency: Mapping[str, Any]) -> list[str]:
    band = frequency["dominant_band"]
    lines = [
        "",
        "Residual power above the white-noise floor, by band relative to the sensor corner "
        "frequency 1/(2 pi tau):",
        "",
    ]
    lines += [f"- {k}: {100 * v:.1f} %" for k, v in frequency.items() if k != "dominant_band"]
    lines += [
        f"- octave holding most of it: {band['low_hz']:.3g} - {band['high_hz']:.3g} Hz "
        f"({100 * band['share']:.1f} %; excess {band['excess_rms']:.3g} K RMS)",
    ]
    return lines


def _header(d: Diagnosis) -> list[str]:
    n = d.noise
    lines = [
        "# Discrepancy diagnosis",
        "",
        f"{d.measured.size} samples at {d.sample_interval:g} s "
        f"({d.measured.size * d.sample_interval / 60:.1f} min). White noise: reference "
        f"{d.noise_std[0]:.3g} K ({n.get('reference_source', '-')}), measured "
        f"{d.noise_std[1]:.3g} K ({n.get('measured_source', '-')}). Residual floor of a perfect "
        f"model {math.sqrt(d.noise_floor):.3g} K RMS: white noise of both signals "
        f"{math.sqrt(n.get('white_floor', 0.0)):.3g} K, gas jumps between samples "
        f"{math.sqrt(n.get('jump_floor', 0.0)):.3g} K, curvature of the input between samples "
        f"{math.sqrt(n.get('roughness_floor', 0.0)):.3g} K (RMS each).",
        "",
    ]
    if d.verdict is not None:
        v = d.verdict
        lines += [
            "## Verdict",
            "",
            f"**{v.verdict}**. {v.sentence}",
            "",
            f"Misfit to noise {v.misfit_to_noise:.3g} (baseline {v.baseline_misfit_to_noise:.3g});"
            f" a misfit is structured when it exceeds {MISFIT_LIMIT:.3g} x the floor and is not "
            f"white (Ljung-Box p = {v.ljung_box_p:.3g}, limit {STRUCTURE_P:g}).",
            "",
        ]
    return lines


def _ladder(d: Diagnosis) -> list[str]:
    base, final = d.baseline, d.final
    lines = [
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
            f"{_pct(ev.get('gap_closed'))} | {_fmt(ev.get('likelihood_ratio'))} | "
            f"{_fmt(ev.get('delta_bic'))} |"
        )
    lines += [
        "",
        "Delta BIC: the BIC of the model without the effect minus that with it, with the "
        "effective sample size from the residual autocorrelation (> 0: evidence for the effect; "
        "the same sign in the steps below and in the JSON). quantisation is detected from the "
        "readings' grid, not fitted: it changes the noise floor, not the model.",
        "",
        "![measured vs simulated](fit.png)",
        "",
        "## Baseline",
        "",
        "First order, unity gain: "
        + ", ".join(_param(k, v) for k, v in base.params.items())
        + f"; RMSE {base.rmse:.4g} K, fit {base.fit_percent:.2f} %.",
        "",
    ]
    return lines


def _baseline_disagreement(d: Diagnosis) -> list[str]:
    loc = d.localisation
    tb = d.tests_baseline
    lines = ["## Where the baseline disagrees", "", "Largest disagreement windows:"]
    lines += _windows(loc["windows"])
    lines += _regimes(loc["regimes"])
    lines += _frequency(loc["frequency"])
    lines += ["", "Physics signatures:", ""]
    lines += [f"- {name}: {_fmt(v)}" for name, v in loc["signatures"].items()]
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
    ]
    return lines


def _remaining(d: Diagnosis) -> list[str]:
    m = d.misfit
    if not m:
        return []
    lines = [
        "## Where the remaining misfit lives",
        "",
        f"Final model ({', '.join(d.final.effects) or 'first order'}): RMSE {d.final.rmse:.4g} K"
        f" against the floor of {math.sqrt(d.noise_floor):.3g} K.",
    ]
    lines += _windows(m["windows"])
    lines += _regimes(m["regimes"])
    lines += _frequency(m["frequency"])
    return [*lines, ""]


def _steps(d: Diagnosis) -> list[str]:
    lines = ["## Steps", ""]
    for i, s in enumerate(d.steps, 1):
        lines += [
            f"### {i}. {s.effect}",
            "",
            "Parameters: " + ", ".join(_param(k, v) for k, v in s.params.items()),
            "",
            f"RMSE {s.rmse_before:.4g} -> {s.rmse_after:.4g} K. Evidence: "
            + ", ".join(
                f"{k} = {_fmt(v)}" for k, v in s.evidence.items() if not isinstance(v, Mapping)
            )
            + ".",
        ]
        if s.candidates:
            lines += [
                "",
                "| candidate | RMSE (K) | gap closed | likelihood ratio | delta BIC "
                "| size / minimum | significant |",
                "|---|---|---|---|---|---|---|",
            ]
            for name, c in s.candidates.items():
                lines.append(
                    f"| {name} | {c['rmse']:.4g} | {_pct(c['gap_closed'])} | "
                    f"{_fmt(c['likelihood_ratio'])} | {_fmt(c['delta_bic'])} | "
                    f"{_fmt(c['effect_size_over_minimum'])} | {_fmt(c['significant'])} |"
                )
        lines.append("")
    if d.last_round:
        lines += [
            "### Last round: nothing significant remains",
            "",
            "| candidate | RMSE (K) | gap closed | likelihood ratio | delta BIC | size / minimum |",
            "|---|---|---|---|---|---|",
        ]
        for name, c in d.last_round.items():
            lines.append(
                f"| {name} | {c['rmse']:.4g} | {_pct(c['gap_closed'])} | "
                f"{_fmt(c['likelihood_ratio'])} | {_fmt(c['delta_bic'])} | "
                f"{_fmt(c['effect_size_over_minimum'])} |"
            )
        lines.append("")
    if d.dropped:
        lines += [f"Dropped as redundant given the others: {', '.join(d.dropped)}.", ""]
    return lines


def markdown(d: Diagnosis) -> str:
    lines = [*_header(d), *_ladder(d), *_baseline_disagreement(d), *_remaining(d), *_steps(d)]
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
