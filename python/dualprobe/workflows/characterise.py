"""The pipeline behind `dualprobe characterise`: load, validate, estimate, reconstruct, report."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from dualprobe.estimation import METHODS, PairEstimate, characterise_pair
from dualprobe.io import EstimationError, InputError, Recording, load_recording, write_columns
from dualprobe.reconstruction import MODES as RECONSTRUCTION_MODES
from dualprobe.reconstruction import reconstruct_pair
from dualprobe.report.json import jsonable
from dualprobe.report.json import write_json as write_json_document

__all__ = [
    "METHODS",
    "RECONSTRUCTION_MODES",
    "Characterisation",
    "characterise_arrays",
    "characterise_file",
    "load_pair",
]

ORDERS = (1, 2)


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

    def to_json_dict(self) -> dict[str, Any]:
        """The `--json` document (see the issue 2 specification)."""
        est = self.estimate
        sensors: list[dict[str, Any]] = []
        for index, column in enumerate(self.columns):
            sensor: dict[str, Any] = {
                "column": column,
                "time_constants": list(est.time_constants[index]),
            }
            if est.time_constants_heat is not None:
                sensor["time_constants_heat"] = list(est.time_constants_heat[index])
            if est.time_constants_cool is not None:
                sensor["time_constants_cool"] = list(est.time_constants_cool[index])
            sensors.append(sensor)
        document: dict[str, Any] = {
            "method": est.method,
            "order": est.order,
            "sample_interval": est.sample_interval,
            "status": est.status,
            "beta": est.beta,
            "sensors": sensors,
            "noise_std": list(est.noise_std),
            "identifiability": dict(est.identifiability),
        }
        if self.reference_column is not None:
            document["reconstruction"] = {
                "rmse_vs_reference": self.rmse_vs_reference,
                "reference_column": self.reference_column,
                "mode": self.reconstruction_mode,
            }
        return jsonable(document)

    def summary(self) -> str:
        """A short human-readable summary (a few lines)."""
        est = self.estimate
        lines = []
        where = f"{self.source}: " if self.source else ""
        lines.append(
            f"{where}{self.time.size} samples, sample interval {est.sample_interval:.6g} s"
        )
        lines.append(f"method {est.method}, order {est.order}: {est.status}")
        for index, column in enumerate(self.columns):
            taus = ", ".join(f"{tau:.5g}" for tau in est.time_constants[index])
            text = f"  {column}: time constant{'s' if len(est.time_constants[index]) > 1 else ''}"
            text += f" {taus} s"
            if est.time_constants_heat is not None and est.time_constants_cool is not None:
                heat = ", ".join(f"{tau:.5g}" for tau in est.time_constants_heat[index])
                cool = ", ".join(f"{tau:.5g}" for tau in est.time_constants_cool[index])
                text += f" (heating {heat} s, cooling {cool} s)"
            lines.append(text)
        if self.requested_order is not None and est.order != self.requested_order:
            lines.append(
                f"  note: order {self.requested_order} requested; the data support order "
                f"{est.order}"
            )
        message = est.identifiability.get("message")
        if message:
            lines.append(f"  note: {' '.join(str(message).split())}")
        noise = ", ".join(f"{s:.3g}" for s in est.noise_std)
        lines.append(f"  noise std: {noise} K" + (f"; beta {est.beta:.6g}" if est.beta else ""))
        if self.gas_estimate is not None:
            valid = int(np.count_nonzero(np.isfinite(self.gas_estimate)))
            text = f"reconstruction ({self.reconstruction_mode}): {valid} of "
            text += f"{self.gas_estimate.size} samples"
            if self.rmse_vs_reference is not None:
                text += f", RMSE vs {self.reference_column} {self.rmse_vs_reference:.4g} K"
            lines.append(text)
        return "\n".join(lines)


def _parse_noise_std(noise_std: float | Sequence[float] | None) -> tuple[float, float] | None:
    if noise_std is None:
        return None
    values = (
        [float(noise_std)] * 2
        if isinstance(noise_std, (int, float, np.floating))
        else [float(v) for v in noise_std]
    )
    if len(values) == 1:
        values *= 2
    if len(values) != 2:
        raise InputError(f"noise std: expected one or two values, got {len(values)}")
    for value in values:
        if not math.isfinite(value) or value < 0.0:
            raise InputError(f"noise std: must be finite and >= 0, got {value!r}")
    return values[0], values[1]


def _format_taus(taus: Sequence[Sequence[float]]) -> str:
    return " and ".join("(" + ", ".join(f"{tau:.5g}" for tau in sensor) + ") s" for sensor in taus)


def _check_excitation(t1: np.ndarray, t2: np.ndarray, columns: tuple[str, str]) -> None:
    for column, values in zip(columns, (t1, t2), strict=True):
        if np.ptp(values) == 0.0:
            raise EstimationError(
                f"no excitation: column {column!r} is constant ({values[0]:.6g}); the time "
                "constants need a recording in which the temperature changes"
            )


def _relative_static(estimate: PairEstimate) -> tuple[float, float] | None:
    """Sensor 2's gain and offset relative to sensor 1 when the estimate found them
    (affine static model); the reconstruction is then in sensor 1's calibration."""
    details = estimate.details
    if details.get("static_model") != "affine":
        return None
    gain, offset = details.get("gain_ratio"), details.get("offset")
    if not isinstance(gain, (int, float)) or not isinstance(offset, (int, float)):
        return None
    return float(gain), float(offset)


def characterise_arrays(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    time: np.ndarray | None = None,
    columns: tuple[str, str] = ("T_m1", "T_m2"),
    method: str = "auto",
    order: int = 1,
    hysteresis: bool = False,
    noise_std: float | Sequence[float] | None = None,
    reconstruction: str | None = "smoother",
    reference: np.ndarray | None = None,
    reference_column: str | None = None,
    source: str | None = None,
) -> Characterisation:
    """Characterise a sensor pair from two sampled signals and optionally reconstruct the gas.

    Raises InputError for unusable arguments and EstimationError when the data do not allow an
    estimate (no excitation, infeasible or insufficiently excited estimate).
    """
    t1 = np.asarray(t1, dtype=np.float64)
    t2 = np.asarray(t2, dtype=np.float64)
    if t1.ndim != 1 or t1.shape != t2.shape:
        raise InputError(f"sensor signals must be 1-D of equal length, got {t1.shape}, {t2.shape}")
    if not (math.isfinite(ts) and ts > 0.0):
        raise InputError(f"sample interval must be finite and > 0, got {ts!r}")
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if order not in ORDERS:
        raise InputError(f"order must be 1 or 2, got {order!r}")
    if reconstruction is not None and reconstruction not in RECONSTRUCTION_MODES:
        raise InputError(
            f"reconstruction must be one of {', '.join(RECONSTRUCTION_MODES)}, "
            f"got {reconstruction!r}"
        )
    for column, values in zip(columns, (t1, t2), strict=True):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise InputError(f"sample {int(bad[0])}, column {column!r}: non-finite value")
    if reference is not None:
        reference = np.asarray(reference, dtype=np.float64)
        if reference.shape != t1.shape:
            raise InputError("reference must have the same length as the sensor signals")
    sigma = _parse_noise_std(noise_std)
    _check_excitation(t1, t2, columns)

    estimate = characterise_pair(
        t1, t2, ts, method=method, order=order, hysteresis=hysteresis, noise_std=sigma
    )
    if estimate.status != "ok":
        detail = estimate.details.get("message") if estimate.details else None
        text = f"estimation failed: {estimate.status.replace('_', ' ')}"
        if detail:
            text += f": {detail}"
        else:
            text += {
                "insufficient_excitation": " (the signals do not change enough to identify "
                "the time constants; record a temperature change)",
                "infeasible": " (no physical time constants fit these signals; check that "
                "--sensor1 is the faster sensor's column and the columns are right)",
            }.get(estimate.status, "")
        raise EstimationError(text)

    gas: np.ndarray | None = None
    rmse: float | None = None
    if reconstruction is not None:
        heat = estimate.time_constants_heat
        cool = estimate.time_constants_cool
        hysteretic = hysteresis and heat is not None and cool is not None
        try:
            gas = np.asarray(
                reconstruct_pair(
                    t1,
                    t2,
                    ts,
                    heat[0] if hysteretic and heat is not None else estimate.time_constants[0],
                    heat[1] if hysteretic and heat is not None else estimate.time_constants[1],
                    mode=reconstruction,
                    noise_std=estimate.noise_std,
                    taus1_cool=cool[0] if hysteretic and cool is not None else None,
                    taus2_cool=cool[1] if hysteretic and cool is not None else None,
                    relative_static=_relative_static(estimate),
                ),
                dtype=np.float64,
            )
        except ValueError as exc:
            # the inputs were validated above: what is left is the data not supporting the
            # reconstruction with these time constants (exit 3, not 2)
            raise EstimationError(
                f"reconstruction ({reconstruction}) with time constants "
                f"{_format_taus(estimate.time_constants)} failed: {exc}"
            ) from None
        if gas.shape != t1.shape:
            raise EstimationError(
                f"reconstruction returned {gas.shape[0] if gas.ndim else 0} samples for "
                f"{t1.size} inputs"
            )
        if reference is not None:
            valid = np.isfinite(gas)
            if not np.any(valid):
                raise EstimationError("reconstruction produced no values to compare")
            rmse = float(np.sqrt(np.mean((gas[valid] - reference[valid]) ** 2)))
    if time is None:
        time = np.arange(t1.size, dtype=np.float64) * ts
    return Characterisation(
        estimate=estimate,
        columns=columns,
        time=np.asarray(time, dtype=np.float64),
        gas_estimate=gas,
        reconstruction_mode=reconstruction if gas is not None else None,
        reference_column=reference_column if reference is not None else None,
        rmse_vs_reference=rmse,
        source=source,
        requested_order=order,
    )


def load_pair(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    time: str | None = "t",
    time_unit: str | None = None,
    sample_interval: float | None = None,
) -> Recording:
    """Load the columns of a recording in any format (CSV, Parquet, MDF4) for characterise:
    jitter resampled, units converted (notes say so); a record with a gap is refused with a
    message naming the gap (until the estimation uses the segments together)."""
    if not time and sample_interval is None:
        raise InputError("without a time column the sample interval must be given")
    recording = load_recording(
        path, columns, time=time or None, time_unit=time_unit, sample_interval=sample_interval
    )
    recording.require_contiguous("characterise")
    return recording


def characterise_file(
    path: str | os.PathLike[str],
    *,
    time: str | None = "t",
    sensor1: str = "T_m1",
    sensor2: str = "T_m2",
    sample_interval: float | None = None,
    method: str = "auto",
    order: int = 1,
    hysteresis: bool = False,
    noise_std: float | Sequence[float] | None = None,
    reference: str | None = None,
    reconstruction: str | None = "smoother",
    time_unit: str | None = None,
) -> Characterisation:
    """Load a recording (CSV, Parquet or MDF4) and characterise it (see
    :func:`characterise_arrays`).

    Without a time column (``time=None`` or ``""``) the sample interval must be given;
    ``time_unit`` (s, ms, us, min) overrides the unit read from the time column's header.
    """
    if sensor1 == sensor2:
        raise InputError(f"--sensor1 and --sensor2 name the same column {sensor1!r}")
    wanted = [sensor1, sensor2] + ([reference] if reference else [])
    recording = load_pair(
        path, wanted, time=time, time_unit=time_unit, sample_interval=sample_interval
    )
    columns = recording.columns
    result = characterise_arrays(
        columns[sensor1],
        columns[sensor2],
        recording.sample_interval,
        time=recording.t,
        columns=(sensor1, sensor2),
        method=method,
        order=order,
        hysteresis=hysteresis,
        noise_std=noise_std,
        reconstruction=reconstruction,
        reference=columns[reference] if reference else None,
        reference_column=reference,
        source=str(path),
    )
    return replace(result, notes=recording.notes)


def write_json(result: Characterisation, path: str | os.PathLike[str]) -> None:
    """Write the `--json` document (strict JSON: non-finite numbers become null)."""
    write_json_document(result.to_json_dict(), path)


def write_reconstruction(result: Characterisation, path: str | os.PathLike[str]) -> None:
    """Write the `--output` CSV: `t,T_g_hat`, one row per input row, `nan` where no value."""
    if result.gas_estimate is None:
        raise InputError("no reconstruction to write")
    write_columns(path, {"t": result.time, "T_g_hat": result.gas_estimate})
