"""What a diagnosis returns: the ladder of :class:`Step` s and the :class:`Diagnosis`."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.diagnose.fit import ModelFit
from dualprobe.report.json import jsonable

__all__ = [
    "Diagnosis",
    "Step",
]


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

    @property
    def effects(self) -> list[str]:
        return [s.effect for s in self.steps]

    @property
    def residual_white(self) -> bool:
        return bool(self.tests_final["white"])

    def to_json_dict(self) -> dict[str, Any]:
        """The issue's JSON document."""
        return jsonable(
            {
                "baseline": {
                    "model": "first_order",
                    "params": dict(self.baseline.params),
                    "rmse": self.baseline.rmse,
                    "fit_percent": self.baseline.fit_percent,
                },
                "steps": [
                    {
                        "effect": s.effect,
                        "params": s.params,
                        "rmse_before": s.rmse_before,
                        "rmse_after": s.rmse_after,
                        "evidence": s.evidence,
                        "where": s.where,
                    }
                    for s in self.steps
                ],
                "effects": self.effects,
                "final_rmse": self.final.rmse,
                "residual_white": self.residual_white,
            }
        )

    def summary(self) -> str:
        lines = [
            f"baseline first order: tau = {self.baseline.tau:.4g} s, "
            f"RMSE {self.baseline.rmse:.4g} K, fit {self.baseline.fit_percent:.1f} %",
        ]
        for s in self.steps:
            details = ", ".join(f"{k} = {v:.4g}" for k, v in s.params.items())
            lines.append(
                f"+ {s.effect} ({details}): RMSE {s.rmse_before:.4g} -> {s.rmse_after:.4g} K, "
                f"gap closed {100 * s.evidence['gap_closed']:.0f} %"
            )
        if not self.steps:
            lines.append("no missing effect found: the first-order model explains the data")
        lines.append(
            f"final RMSE {self.final.rmse:.4g} K (noise {self.noise_std[1]:.3g} K), residual "
            f"{'white' if self.residual_white else 'not white'}"
        )
        return "\n".join(lines)

    def write_report(self, directory: str | os.PathLike[str]) -> Path:
        """Markdown report with figures in `directory`; returns the Markdown path."""
        from dualprobe.diagnose.report import write_report  # the report builds on this module

        return write_report(self, directory)
