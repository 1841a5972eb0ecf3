"""What a diagnosis returns: the ladder of :class:`Step` s and the :class:`Diagnosis`."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.diagnose.catalogue import UNITS, with_units
from dualprobe.diagnose.fit import ModelFit
from dualprobe.diagnose.verdict import Verdict
from dualprobe.report.json import jsonable

__all__ = [
    "Diagnosis",
    "Step",
    "format_param",
]


def format_param(name: str, value: float, digits: int = 4) -> str:
    """``name = value unit`` (no unit for dimensionless parameters)."""
    unit = UNITS.get(name, "")
    return f"{name} = {value:.{digits}g}" + (f" {unit}" if unit not in ("", "1") else "")


@dataclass(frozen=True)
class Step:
    """One rung of the ladder: the effect added, its parameters and the evidence."""

    effect: str
    params: dict[str, float]
    rmse_before: float
    rmse_after: float
    evidence: dict[str, Any]
    where: list[dict[str, Any]]
    model: ModelFit
    candidates: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`."""

    time: np.ndarray
    reference: np.ndarray
    measured: np.ndarray
    sample_interval: float
    noise_std: tuple[float, float]  # (reference, measured)
    noise_floor: float  # mean square residual a perfect model leaves (K^2)
    baseline: ModelFit
    steps: tuple[Step, ...]
    final: ModelFit
    localisation: dict[str, Any]  # of the baseline residual
    tests_baseline: dict[str, Any]
    tests_final: dict[str, Any]
    dropped: tuple[str, ...] = ()  # effects added and then found redundant
    last_round: dict[str, dict[str, Any]] = field(default_factory=dict)  # none significant
    flow: np.ndarray | None = None
    noise: dict[str, Any] = field(default_factory=dict)  # levels, their sources, the floors
    verdict: Verdict | None = None
    misfit: dict[str, Any] = field(default_factory=dict)  # localisation of the final residual
    notes: tuple[str, ...] = ()  # the loader's (jitter resampled, rows bridged, units)

    @property
    def effects(self) -> list[str]:
        return [s.effect for s in self.steps]

    @property
    def residual_white(self) -> bool:
        return bool(self.tests_final["white"])

    @property
    def misfit_to_noise(self) -> float:
        return self.verdict.misfit_to_noise if self.verdict else float("nan")

    def to_json_dict(self) -> dict[str, Any]:
        """The JSON document: the issue-5 ladder plus the verdict, the noise and where the
        remaining misfit lives. Units: K, s, degC; every params block has its "units"."""
        verdict = self.verdict
        return jsonable(
            {
                "baseline": {
                    "model": "first_order",
                    "params": dict(self.baseline.params),
                    "units": with_units(self.baseline.params),
                    "rmse": self.baseline.rmse,
                    "fit_percent": self.baseline.fit_percent,
                },
                "steps": [
                    {
                        "effect": s.effect,
                        "params": s.params,
                        "units": with_units(s.params),
                        "rmse_before": s.rmse_before,
                        "rmse_after": s.rmse_after,
                        "evidence": s.evidence,
                        "where": s.where,
                    }
                    for s in self.steps
                ],
                "effects": self.effects,
                "final_params": dict(self.final.params),
                "final_rmse": self.final.rmse,
                "residual_white": self.residual_white,
                "notes": list(self.notes),
                "verdict": verdict.verdict if verdict else None,
                "misfit_to_noise": self.misfit_to_noise,
                "summary": verdict.sentence if verdict else "",
                "noise": self.noise,
                "misfit": {**(verdict.to_dict() if verdict else {}), **self.misfit},
            }
        )

    def summary(self) -> str:
        """The human summary: the ladder with units, then the verdict in one sentence."""
        lines = [
            f"baseline first order: tau = {self.baseline.tau:.4g} s, "
            f"RMSE {self.baseline.rmse:.4g} K, fit {self.baseline.fit_percent:.1f} %",
        ]
        for s in self.steps:
            details = ", ".join(format_param(k, v) for k, v in s.params.items())
            closed = s.evidence.get("gap_closed")
            gain = f", gap closed {100 * closed:.0f} %" if closed is not None else ""
            lines.append(
                f"+ {s.effect} ({details}): RMSE {s.rmse_before:.4g} -> {s.rmse_after:.4g} K{gain}"
            )
        lines.append(
            f"noise: reference {self.noise_std[0]:.3g} K, measured {self.noise_std[1]:.3g} K; "
            f"floor of a perfect model {self.noise_floor**0.5:.3g} K RMS"
        )
        if self.verdict is not None:
            lines.append(f"verdict: {self.verdict.verdict}. {self.verdict.sentence}")
        return "\n".join(lines)

    def write_report(self, directory: str | os.PathLike[str]) -> Path:
        """Markdown report with figures in `directory`; returns the Markdown path."""
        from dualprobe.diagnose.report import write_report  # the report builds on this module

        return write_report(self, directory)
