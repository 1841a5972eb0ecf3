"""What `dualprobe characterise` reports: the :class:`Characterisation` of one recording, its
JSON document and its human summary (with the standard uncertainties, the flow law and the
model check)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualprobe.estimation import PairEstimate
from dualprobe.estimation.settings import SHEATHED_SCHEDULE_ERROR
from dualprobe.reconstruction import Bandwidth
from dualprobe.report.json import jsonable
from dualprobe.workflows.checks import ModelCheck

__all__ = ["SHEATHED_STD_NOTE", "TRACKED_NOISE_STD_NOTE", "TRACKED_STD_NOTE", "Characterisation"]

TRACKED_STD_NOTE = ("T_g_std assumes these tracked time constants: their own error, which "
                    "can dominate the gas's without a flow signal, is not in it")
TRACKED_NOISE_STD_NOTE = ("T_g_std includes the part of the tracked time constants' error that "
                          "follows the noise (psi_noise), not a bias of theirs: without a flow "
                          "signal it can still be too small")
SHEATHED_STD_NOTE = ("T_g_std includes the tracked time constants' noise (psi_noise) and the "
                     "typical error of time constants tracked through sheaths "
                     f"({SHEATHED_SCHEDULE_ERROR:.0%} RMS per row on simulated drive cycles), "
                     "not this record's own: it can still be too small")


def _fmt(value: float, std: float | None = None) -> str:
    """``x ± s`` with s to two significant digits and x to the same decimal place."""
    if std is None or not math.isfinite(value):
        return f"{value:.5g}"
    if not math.isfinite(std):
        return f"{value:.5g} ± inf"
    if std <= 0.0:
        return f"{value:.5g} ± 0"
    decimals = max(1 - math.floor(math.log10(std)), 0)
    if decimals > 6:
        # a column in other units (a gain of 1e-12 printed as 0.0000000000 ± 0.0000000000)
        return f"{value:.4g} ± {std:.2g}"
    return f"{value:.{decimals}f} ± {std:.{decimals}f}"


# The flow column's noise in the time constants (|m| times its row noise) from which the
# summary notes it: 0.5 %, a tenth of the 5 % bound on the per-row time constants (a
# clean simulated column: 4e-8; 1 % noise on the mass flow at m 0.5 gives 0.5 %)
FLOW_NOISE_NOTE = 0.005
_UNIT_GAIN = 0.2  # of a gain ratio off 1: see Characterisation._static_line
_UNIT_OFFSET = 100.0  # K, ditto


@dataclass(frozen=True)
class Characterisation:
    """Result of characterising one recording of a sensor pair."""

    estimate: PairEstimate
    columns: tuple[str, str]
    time: np.ndarray  # time stamps of the input rows
    gas_estimate: np.ndarray | None  # reconstructed gas temperature per input row (NaN: none)
    reconstruction_mode: str | None
    reference_column: str | None
    rmse_vs_reference: float | None
    source: str | None = None
    requested_order: int | None = None
    notes: tuple[str, ...] = ()  # one-line notes of the loader (units, jitter, interpolation)
    gas_std: np.ndarray | None = None  # posterior standard deviation of the reconstruction
    bandwidth: Bandwidth | None = None  # the smoother's: what gas_std covers
    model_check: ModelCheck | None = None
    flow: np.ndarray | None = None  # the flow column, when a flow law was asked for
    signals: tuple[np.ndarray, np.ndarray] | None = None  # the two sensors' readings
    reference: np.ndarray | None = None  # the reference column, when given

    # ---------------------------------------------------------------------------------------
    def time_constants_per_row(self) -> tuple[np.ndarray, np.ndarray]:
        """Each sensor's dominant time constant in effect at every row (flow law or tracked:
        tau / psi; else constant)."""
        est = self.estimate
        psi = est.flow_model.psi if est.flow_model is not None else np.ones(self.time.size)
        return est.time_constants[0][0] / psi, est.time_constants[1][0] / psi

    def _std(self, name: str) -> float | None:
        conf = self.estimate.confidence
        return None if conf is None else conf.std.get(name)

    def _static_line(self) -> str:
        """The affine map between the sensors' scales (the JSON's ``static_model``)."""
        gain = float(self.estimate.details.get("gain_ratio", 1.0))
        offset = float(self.estimate.details.get("offset", 0.0))
        first, second = self.columns
        sign = "-" if offset < 0.0 else "+"
        text = (f"  static map: {first} = {_fmt(gain, self._std('gain_ratio'))} x {second} "
                f"{sign} {_fmt(abs(offset), self._std('offset'))} (the reconstruction is in "
                f"{first}'s scale)")
        # sensors' own gains differ by a few per cent and offsets by a few K; beyond this the
        # columns are more likely in different units (K and degC: 273.15; degF: 1.8)
        if abs(gain - 1.0) > _UNIT_GAIN or abs(offset) > _UNIT_OFFSET:
            text += "; columns in different units?"
        return text

    def _sensor(self, index: int, column: str) -> dict[str, Any]:
        est = self.estimate
        taus = list(est.time_constants[index])
        sensor: dict[str, Any] = {"column": column, "time_constants": taus}
        conf = est.confidence
        names = [f"tau{index + 1}_{j}" for j in range(len(taus))]
        if conf is not None:
            sensor["time_constants_std"] = [conf.std.get(n, math.nan) for n in names]
            sensor["identifiable"] = [conf.identifiable.get(n, False) for n in names]
            sensor["identifiability_reasons"] = [conf.reasons.get(n, []) for n in names]
        for kind in ("heat", "cool"):
            values = getattr(est, f"time_constants_{kind}")
            if values is not None:
                sensor[f"time_constants_{kind}"] = list(values[index])
                if conf is not None:
                    name = f"tau{index + 1}_{kind}"
                    sensor[f"time_constants_{kind}_std"] = [conf.std.get(name, math.nan)]
                    sensor[f"identifiable_{kind}"] = [conf.identifiable.get(name, False)]
        return sensor

    def _flow_model(self) -> dict[str, Any] | None:
        model = self.estimate.flow_model
        if model is None:
            return None
        doc: dict[str, Any] = {"kind": model.kind, "column": model.column,
                               "exponent": model.exponent if model.kind != "constant" else 0.0,
                               "exponent_std": self._std("exponent")
                               if model.kind == "power_law" else (
                                   model.exponent_std if model.kind == "curve" else 0.0),
                               "reference_flow": model.reference_flow,
                               "delay": model.delay,
                               "level_sensitivity": model.level_sensitivity,
                               "level_reference": model.level_reference,
                               "level_curvature": model.level_curvature,
                               "flow_noise": model.evidence.get("flow_noise", math.nan),
                               "evidence": dict(model.evidence)}
        if model.flow_range is not None:
            doc["flow_range"] = list(model.flow_range)
        taus = self.estimate.time_constants
        if model.curve is not None:
            flows = model.curve.knots
            psi = model.curve.values
        elif model.kind == "power_law" and model.flow_range is not None:
            flows = np.geomspace(model.flow_range[0], model.flow_range[1], 9)
            psi = (flows / float(model.reference_flow)) ** model.exponent
        else:
            flows = psi = None
        if flows is not None and psi is not None:
            doc["curve"] = {"flow": list(flows),
                            "time_constants": [list(taus[0][0] / psi), list(taus[1][0] / psi)]}
        return doc

    def reconstruction_doubts(self) -> list[str]:
        """Why the reconstruction should not be trusted (empty: no reason known): it rests on
        a dominant time constant the data do not pin (its error scales the lag correction
        one to one), or on a model that does not explain the signals."""
        conf = self.estimate.confidence
        doubts = []
        if conf is not None:
            for index, column in enumerate(self.columns):
                name = f"tau{index + 1}_0"
                if not conf.identifiable.get(name, True):
                    doubts.append(f"it rests on {column}'s time constant, which the data do "
                                  "not determine: the lag correction may swing by as much")
        if self.model_check is not None and not self.model_check.adequate:
            doubts.append("the model does not explain both signals (see the model check)"
                          if not self.model_check.fits else "the time constants it rests on "
                          "are not determined by these data, or not shown to be (see the "
                          "model check)")
        return doubts

    def to_json_dict(self) -> dict[str, Any]:
        """The `--json` document."""
        est = self.estimate
        document: dict[str, Any] = {
            "method": est.method,
            "order": est.order,
            "sample_interval": est.sample_interval,
            "status": est.status,
            "beta": est.beta,
            "sensors": [self._sensor(i, c) for i, c in enumerate(self.columns)],
            "noise_std": list(est.noise_std),
            "identifiability": {k: v for k, v in est.identifiability.items()},
            "notes": list(self.notes),
        }
        static = est.details.get("static_model")
        if static is not None:
            document["static_model"] = {
                "kind": static,
                "gain_ratio": est.details.get("gain_ratio", 1.0),
                "gain_ratio_std": self._std("gain_ratio") if static == "affine" else 0.0,
                "offset": est.details.get("offset", 0.0),
                "offset_std": self._std("offset") if static == "affine" else 0.0,
            }
        flow = self._flow_model()
        if flow is not None:
            document["flow_model"] = flow
        if est.confidence is not None:
            document["uncertainty"] = {
                "method": "delete-one-block jackknife with the filter time constant at tf/2 "
                          "and 2 tf",
                "blocks": est.confidence.blocks, "block_length": est.confidence.block_length,
                "notes": list(est.confidence.notes),
            }
        if self.model_check is not None:
            document["model_check"] = self.model_check.to_json_dict()
        if self.gas_estimate is not None:
            doubts = self.reconstruction_doubts()
            document["reconstruction"] = {
                "mode": self.reconstruction_mode,
                "rmse_vs_reference": self.rmse_vs_reference,
                "reference_column": self.reference_column,
                "reliable": not doubts,
                "doubts": doubts,
            }
            if self.bandwidth is not None:
                document["reconstruction"].update(self.bandwidth.to_json_dict())
        return jsonable(document)

    # ---------------------------------------------------------------------------------------
    def summary(self) -> str:
        """A short human-readable summary (a few lines)."""
        est = self.estimate
        lines = []
        where = f"{self.source}: " if self.source else ""
        lines.append(f"{where}{self.time.size} samples, sample interval "
                     f"{est.sample_interval:.6g} s")
        check = self.model_check
        # a doubt is not a misfit: the signals fit, the data do not vouch for the result
        status = (est.status if check is None or check.adequate
                  else "signals fit, result doubtful" if check.fits else "model misfit")
        lines.append(f"method {est.method}, order {est.order}: {status}")
        model = est.flow_model
        at = ""
        if model is not None and model.kind in ("power_law", "curve"):
            at = f" at the reference flow {model.reference_flow:.4g}"
        elif model is not None and model.kind == "tracked":
            at = " (record average; tracked over time)"
        conf = est.confidence
        for index, column in enumerate(self.columns):
            parts = []
            for j, tau in enumerate(est.time_constants[index]):
                name = f"tau{index + 1}_{j}"
                text = _fmt(tau, None if conf is None else conf.std.get(name))
                if conf is not None and not conf.identifiable.get(name, True):
                    text += " (not identifiable: " + "; ".join(conf.reasons.get(name, [])) + ")"
                parts.append(text)
            plural = "s" if len(est.time_constants[index]) > 1 else ""
            line = f"  {column}: time constant{plural} {', '.join(parts)} s{at}"
            if est.time_constants_heat is not None and est.time_constants_cool is not None:
                heat = _fmt(est.time_constants_heat[index][0], self._std(f"tau{index + 1}_heat"))
                cool = _fmt(est.time_constants_cool[index][0], self._std(f"tau{index + 1}_cool"))
                line += f" (heating {heat} s, cooling {cool} s)"
            lines.append(line)
        if model is not None and model.kind != "constant":
            if model.kind == "tracked":
                lo, hi = np.quantile(1.0 / model.psi, [0.05, 0.95])
                noise = model.psi_noise
                spread = (f"; noise moves them by {noise:.1%} RMS (psi_noise)"
                          if math.isfinite(noise) else "")
                lines.append(f"  time constants vary over the record (no flow given): "
                             f"x{lo:.3g} to x{hi:.3g} of the average (5-95 %){spread}")
                held = model.evidence.get("held_share", 0.0)
                if held > 0.0:
                    lines.append(f"  note: the gas stood still over {held:.1%} of the rows: the "
                                 "time constants there are held from the rows around them, "
                                 "not determined by the data")
            else:
                exponent = _fmt(model.exponent, self._std("exponent")
                                if model.kind == "power_law" else None)
                law = "power law" if model.kind == "power_law" else "free curve (monotone)"
                lines.append(f"  flow law: {law}, tau ~ flow^-m, m = {exponent}")
                if model.delay != 0.0:
                    lines.append(f"  the sensors follow the flow column {model.delay:+.3g} s "
                                 "later (transport delay; negative: the column lags them)")
                refresh = model.evidence.get("flow_refresh_rows", 1.0)
                if refresh > 1.0:
                    lines.append(f"  note: the flow column is held for {refresh:.0f} rows per "
                                 "refresh; interpolated between its refreshes")
                noise = model.psi_flow_noise
                if noise >= FLOW_NOISE_NOTE:
                    column_noise = model.evidence["flow_noise"]
                    lines.append(f"  note: the flow column carries {column_noise:.2%} noise from "
                                 f"row to row: the time constants follow it by {noise:.2%} RMS "
                                 "(included in T_g_std)")
                if model.level_reference is not None:
                    b, c = model.level_sensitivity, model.level_curvature
                    ref = f"{model.level_reference:.4g}"
                    per100 = 100.0 * math.expm1(100.0 * b)
                    lines.append(f"  and the gas level: tau ~ exp(b dT + c dT^2), dT = T - {ref}, "
                                 f"b = {b:.3g} per unit of T ({per100:+.3g} % per 100 at {ref}), "
                                 f"c = {c:.3g}; time constants above are at T = {ref}")
        elif model is not None and model.column is not None:
            lines.append("  flow law: constant (the time constants do not follow the flow "
                         "measurably)")
        if self.requested_order is not None and est.order != self.requested_order:
            lines.append(f"  note: order {self.requested_order} requested; the data support "
                         f"order {est.order}")
        fallback = est.identifiability.get("order_fallback")
        if fallback:
            lines.append(f"  note: {fallback}")
        for key in ("message", "common_lag"):
            message = est.identifiability.get(key)
            if message:
                lines.append(f"  note: {' '.join(str(message).split())}")
        if conf is not None:
            lines.extend(f"  note: {note}" for note in conf.notes)
        if est.details.get("static_model") == "affine":
            lines.append(self._static_line())
        noise = ", ".join(f"{s:.3g}" for s in est.noise_std)
        lines.append(f"  noise std: {noise} K" + (f"; beta {est.beta:.6g}" if est.beta else ""))
        if self.gas_estimate is not None:
            valid = int(np.count_nonzero(np.isfinite(self.gas_estimate)))
            text = (f"reconstruction ({self.reconstruction_mode}): {valid} of "
                    f"{self.gas_estimate.size} samples")
            if self.rmse_vs_reference is not None:
                text += f", RMSE vs {self.reference_column} {self.rmse_vs_reference:.4g} K"
            lines.append(text)
            lines.extend(f"warning: reconstruction not reliable: {doubt}"
                         for doubt in self.reconstruction_doubts())
            if self.bandwidth is not None:
                lines.append(f"  note: {self.bandwidth.summary()}")
            if model is not None and model.kind == "tracked" and self.gas_std is not None:
                # measured on separately simulated drive cycles, the gas error below the
                # bandwidth over T_g_std: an RMS of 0.7-1.4 tracked with psi_noise in T_g_std
                # (unsheathed; 1.7-3.6 without it), up to 4.6 where a sheath was absorbed
                noisy = math.isfinite(model.psi_noise)
                note = (SHEATHED_STD_NOTE if model.sheathed_path
                        else TRACKED_NOISE_STD_NOTE if noisy else TRACKED_STD_NOTE)
                lines.append(f"  note: {note}")
        if check is not None:
            lines.extend(check.summary_lines())
        return "\n".join(lines)
