"""The pipeline behind `dualprobe characterise`: load, validate, estimate (with a flow law or
tracked time constants, and standard uncertainties), reconstruct, check the model, report."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from dualprobe.estimation import METHODS, PairEstimate, characterise_pair, relevelled
from dualprobe.estimation.pair import has_level_term
from dualprobe.estimation.reuse import Kept
from dualprobe.io import EstimationError, InputError, Recording, load_recording, write_columns
from dualprobe.reconstruction import MODES as RECONSTRUCTION_MODES
from dualprobe.reconstruction import Bandwidth, Reconstruction
from dualprobe.report.json import write_json as write_json_document
from dualprobe.workflows.characterisation import Characterisation
from dualprobe.workflows.checks import MISFIT_LIMIT, check_model, residual_ratios
from dualprobe.workflows.common_part import common_part_doubt, fallback_reason
from dualprobe.workflows.gas import estimate_gas, noise_levels, residuals_of
from dualprobe.workflows.order_choice import (
    common_lag_note,
    first_order,
    first_order_reason,
    refuse_regimes,
    regimes_reason,
)
from dualprobe.workflows.readings import (
    check_excitation,
    parse_noise_std,
    prepare_readings,
)
from dualprobe.workflows.refusals import (
    refuse_departing_gas,
    refuse_implausible,
    refuse_opposed,
    refuse_undetermined,
)
from dualprobe.workflows.scales import column_scale, in_own_scale, scale_note
from dualprobe.workflows.undetermined import Undetermined, undetermined

__all__ = ["METHODS", "RECONSTRUCTION_MODES", "Characterisation", "characterise_arrays",
           "characterise_file", "load_pair"]

ORDERS = ("auto", 1, 2)


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


def _failure_message(estimate: PairEstimate) -> str:
    """One line saying what in the data prevents an estimate and what would help."""
    detail = estimate.details.get("message") if estimate.details else None
    text = f"estimation failed: {estimate.status.replace('_', ' ')}"
    if detail:
        return f"{text}: {detail}"
    return text + {
        "insufficient_excitation": " (the signals do not change enough to identify the time "
        "constants: record a larger or faster temperature change, or a longer record)",
        "infeasible": " (no physical time constants fit these signals: the sensors may see "
        "different gas temperatures or need another model; try --order 1, --flow or "
        "--hysteresis, or check that --sensor1 is the faster sensor)",
    }.get(estimate.status, "")


def _order(order: int | str, hysteresis: bool) -> tuple[int, int | None]:
    """(order to fit, order requested): "auto" is up to 2 chosen per sensor by evidence (1 with
    the heating/cooling split, which is first order)."""
    if order == "auto":
        return (1 if hysteresis else 2), None
    if order not in (1, 2):
        raise InputError(f"order must be auto, 1 or 2, got {order!r}")
    return int(order), int(order)


def characterise_arrays(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    time: np.ndarray | None = None,
    columns: tuple[str, str] = ("T_m1", "T_m2"),
    method: str = "auto",
    order: int | str = "auto",
    hysteresis: bool = False,
    noise_std: float | Sequence[float] | None = None,
    reconstruction: str | None = "smoother",
    reference: np.ndarray | None = None,
    reference_column: str | None = None,
    source: str | None = None,
    flow: np.ndarray | None = None,
    flow_column: str | None = None,
    track: str = "auto",
    uncertainty: bool = True,
) -> Characterisation:
    """Characterise a sensor pair from two sampled signals and optionally reconstruct the gas.

    ``flow``: a positive flow-like signal per row (the time constants then follow a flow law);
    ``track``: "auto" tracks time constants that vary without a flow signal when the data need
    it, "off" never; ``uncertainty``: standard uncertainties and identifiability (without
    them the order chosen by evidence cannot drop second stages that are not determined, and
    such a fit is refused instead: a drive-cycle pair with the mass flow went to exit 3 with a
    630 s stage where the default gives first order and m within 0.02). Raises
    InputError for unusable arguments and EstimationError when the data do not allow an
    estimate (no excitation, infeasible or implausible result).
    """
    t1 = np.asarray(t1, dtype=np.float64)
    t2 = np.asarray(t2, dtype=np.float64)
    if t1.ndim != 1 or t1.shape != t2.shape:
        raise InputError(f"sensor signals must be 1-D of equal length, got {t1.shape}, {t2.shape}")
    if not (math.isfinite(ts) and ts > 0.0):
        raise InputError(f"sample interval must be finite and > 0, got {ts!r}")
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    fit_order, requested = _order(order, hysteresis)
    if method in ("ls", "tls", "gtls"):
        fit_order = 1 if requested is None else fit_order
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
    readings = (t1, t2)
    sigma = parse_noise_std(noise_std)
    scale = column_scale(t1, t2)  # sensor 2 in sensor 1's scale (workflows/scales.py)
    if scale != 1.0:
        t2 = t2 * scale
        sigma = None if sigma is None else (sigma[0], sigma[1] * scale)
    t1, t2, sigma, held, refreshed = prepare_readings(t1, t2, ts, sigma, columns, time)
    if scale != 1.0:
        held = (*held, scale_note(scale, columns))
    check_excitation(t1, t2, columns)
    svf = method in ("auto", "svf")
    # a first-order fallback repeats the order-independent steps on the same readings (the
    # no-flow tracking, static search, MAPs of psi): kept from the first try (estimation.reuse)
    kept = Kept()

    def estimate_at(fit_order: int) -> PairEstimate:
        with kept:
            return characterise_pair(
                t1, t2, ts, method=method, order=fit_order, hysteresis=hysteresis,
                noise_std=sigma, flow=flow if svf else None, flow_column=flow_column,
                track=track if svf else "off", uncertainty=uncertainty and svf,
            )

    estimate = estimate_at(fit_order)
    if flow is not None and not svf:
        raise InputError(f"--flow needs the SVF method (auto or svf), not {method!r}")
    if requested is None and fit_order == 2 and estimate.status != "ok":
        # order chosen by evidence: data too weak for any second-order model (three or more
        # near-null directions) may still determine a first-order pair, with its uncertainty
        first = estimate_at(1)
        if first.status == "ok":
            estimate = first
    if requested is not None:
        refuse_undetermined(estimate, columns)
    why = first_order_reason(estimate, columns) if requested is None else None
    if why is not None:
        # order chosen by evidence: the order-2 stages are model error absorbed (a (near-)
        # common factor of the two sensors, a stage the filter setting moves), first order and
        # its checks instead
        first = estimate_at(1)
        if first.status == "ok":
            estimate = first_order(first, why)
    if estimate.status != "ok":
        raise EstimationError(_failure_message(estimate))
    if requested is None and estimate.identifiability.get("shared_poles") and estimate.order == 1:
        # order chosen by evidence: a degenerate order-2 fit is the expected outcome for a
        # first-order pair, not news (the shared-pole wording is for an asked-for order 2;
        # what first order leaves open: common_lag_note)
        estimate.identifiability.pop("message", None)

    def levelled(fit: PairEstimate) -> tuple[PairEstimate, tuple[float, float] | None,
                                                  Reconstruction | None]:
        """``fit`` with its level term found again on the gas (estimation/relevel.py),
        whether the gas is asked for or not (one record, one law), its static map, and the
        gas it was found on where kept."""
        static = _relative_static(fit)
        refuse_opposed(static, columns)
        if not (flow is not None and svf and has_level_term(fit)):
            return fit, static, None
        result = estimate_gas(t1, t2, ts, fit, reconstruction or "smoother", hysteresis,
                              static)
        again = _relevelled(t1, t2, ts, fit, result.gas, flow, flow_column, sigma,
                            uncertainty)
        return (fit, static, result) if again is None else (*again, None)

    estimate, static, result = levelled(estimate)
    if requested == 2:
        refuse_regimes(estimate)
    why = regimes_reason(estimate) if requested is None else None
    if why is not None:
        # judged on the law as found again (checks.regime_shared_stage): first order, levelled
        first = estimate_at(1)
        if first.status == "ok":
            estimate, static, result = levelled(first_order(first, why))

    def with_gas(estimate: PairEstimate, static: tuple[float, float] | None,
                 result: Reconstruction | None) -> tuple[PairEstimate, Reconstruction | None,
                                                         Undetermined | None]:
        """``estimate`` with what its order leaves open noted, its gas (where asked) and
        what the data leave of it undetermined (a rival schedule's gas, the common part's)."""
        common_lag = common_lag_note(estimate)
        if common_lag is not None:
            # a new dict: the estimate's own may be shared with a kept fit (estimation.reuse)
            estimate = replace(estimate, identifiability={**estimate.identifiability,
                                                          "common_lag": common_lag})
        if reconstruction is None:
            return estimate, None, None
        if result is None:
            result = estimate_gas(t1, t2, ts, estimate, reconstruction, hysteresis, static)
        doubt = _rival_doubt(t1, t2, ts, estimate, reconstruction, result.gas, result.gas_std)
        if doubt is None and result.gas_std is not None:
            doubt = common_part_doubt(estimate, result.gas, result.gas_std, ts, lambda moved:
                                      estimate_gas(t1, t2, ts, moved, reconstruction,
                                                   hysteresis, static, result).gas)
        return estimate, result, doubt

    estimate, result, doubt = with_gas(estimate, static, result)
    if (requested is None and flow is not None and result is not None and doubt is not None
            and doubt.cause == "common part" and doubt.doubtful):
        # order chosen by evidence: stages whose common part the data leave open are no
        # resolved pair; first order, with the distance to the order-2 gas as uncertainty
        # (common_part.py: the gas 9.95 -> 3.76 K, 21.8 -> 5.4 K)
        first = estimate_at(1)
        if first.status == "ok":
            second = result.gas
            estimate, static, result = levelled(first_order(first, fallback_reason(doubt)))
            estimate, result, doubt = with_gas(estimate, static, result)
            if result is not None and result.gas_std is not None:
                doubt = undetermined(result.gas, second, result.gas_std, ts, cause="order")
    gas: np.ndarray | None = None
    gas_std: np.ndarray | None = None
    resolved: Bandwidth | None = None
    rmse: float | None = None
    residuals = None
    if result is not None:
        gas, gas_std, resolved = result.gas, result.gas_std, result.bandwidth
        if doubt is not None and gas_std is not None:
            gas_std = np.hypot(gas_std, doubt.spread)
        residuals = residuals_of(result, t1, t2, static)
        if reference is not None:
            valid = np.isfinite(gas)
            if not np.any(valid):
                raise EstimationError("reconstruction produced no values to compare")
            rmse = float(np.sqrt(np.mean((gas[valid] - reference[valid]) ** 2)))
    duration = (t1.size - 1) * ts
    refuse_implausible(estimate, duration, columns, residuals, (t1, t2), gas, static, gas_std)
    levels = noise_levels(estimate, static)
    # the paper's method has no misfit statistic of its own: its residuals are checked
    check = (check_model(estimate, residuals, levels, (t1, t2), columns, doubt,
                         refreshed=refreshed)
             if svf or residuals is not None else None)
    if time is None:
        time = np.arange(t1.size, dtype=np.float64) * ts
    return Characterisation(
        estimate=in_own_scale(estimate, scale),
        columns=columns,
        time=np.asarray(time, dtype=np.float64),
        gas_estimate=gas,
        reconstruction_mode=reconstruction if gas is not None else None,
        reference_column=reference_column if reference is not None else None,
        rmse_vs_reference=rmse,
        source=source,
        requested_order=requested,
        gas_std=gas_std,
        bandwidth=resolved,
        model_check=check,
        flow=None if flow is None else np.asarray(flow, dtype=np.float64),
        signals=readings,
        notes=held,
        reference=reference,
    )


def _rival_doubt(
    t1: np.ndarray, t2: np.ndarray, ts: float, estimate: PairEstimate, mode: str,
    gas: np.ndarray, gas_std: np.ndarray | None,
) -> Undetermined | None:
    """The spread between this gas and the rival schedule's (estimation/rival.py), where the
    tracked schedule has one; None where not, or where the rival's result would itself be
    refused or misfit (then it is no rival: a 2 Hz pair's MAP schedule explained the
    cross-relation, 0.57 times the noise, and put the gas 3,180 K RMS off)."""
    model = estimate.flow_model
    rival = model.rival if model is not None else None
    if rival is None or gas_std is None:
        return None
    static = _relative_static(rival)
    try:
        other = estimate_gas(t1, t2, ts, rival, mode, False, static)
        residuals = residuals_of(other, t1, t2, static)
        refuse_implausible(rival, (t1.size - 1) * ts, ("sensor 1", "sensor 2"), residuals,
                           (t1, t2), other.gas, static, other.gas_std)
        # (applied to the product's own gas only while it misfits; a rival must pass it)
        refuse_departing_gas(rival, other.gas, (t1, t2), static,
                             float(rival.details.get("residual_to_noise", math.nan)))  # type: ignore[arg-type]
    except EstimationError:
        return None
    if residuals is not None and max(
            residual_ratios(residuals, noise_levels(rival, static))) > MISFIT_LIMIT:
        return None
    return undetermined(gas, other.gas, gas_std, ts)


def _relevelled(t1: np.ndarray, t2: np.ndarray, ts: float, estimate: PairEstimate,
                gas: np.ndarray, flow: np.ndarray, column: str | None,
                sigma: tuple[float, float] | None, uncertainty: bool,
                ) -> tuple[PairEstimate, tuple[float, float] | None] | None:
    """``estimate`` with its level term searched again on the reconstructed ``gas``, and its
    static map (:func:`_relative_static`), or None (:func:`dualprobe.estimation.relevelled`);
    the order notes this workflow added are kept, the new fit's own identifiability beside
    them."""
    again = relevelled(t1, t2, ts, estimate, gas, flow=flow, flow_column=column,
                       noise_std=sigma, uncertainty=uncertainty)
    static = _relative_static(again) if again is not None else None
    if again is None or (static is not None and not static[0] > 0.0):
        return None  # (a sign-blind gain that turned is no better fit: refuse_opposed)
    ident = dict(again.identifiability)
    for key in ("order_fallback",):
        if key in estimate.identifiability:
            ident[key] = estimate.identifiability[key]
    if "message" not in estimate.identifiability:
        ident.pop("message", None)
    return replace(again, identifiability=ident), static


def load_pair(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    time: str | None = "t",
    time_unit: str | None = None,
    sample_interval: float | None = None,
    required: Sequence[str] = (),
    window: tuple[float | None, float | None] | None = None,
    missing: str = "refuse",
) -> Recording:
    """Load the columns of a recording in any format (CSV, Parquet, MDF4) for characterise:
    jitter resampled, units converted, rows with a missing reading dropped and bridged (notes
    say so; a missing value in a ``required`` column is refused); a record with a gap is
    refused with a message naming the gap (until the estimation uses the segments together)."""
    if not time and sample_interval is None:
        raise InputError("without a time column the sample interval must be given")
    recording = load_recording(
        path, columns, time=time or None, time_unit=time_unit, sample_interval=sample_interval,
        required=required, window=window, missing=missing,
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
    order: int | str = "auto",
    hysteresis: bool = False,
    noise_std: float | Sequence[float] | None = None,
    reference: str | None = None,
    reconstruction: str | None = "smoother",
    time_unit: str | None = None,
    flow: str | None = None,
    track: str = "auto",
    uncertainty: bool = True,
    window: tuple[float | None, float | None] | None = None,
    missing: str = "refuse",
) -> Characterisation:
    """Load a recording (CSV, Parquet or MDF4) and characterise it (see
    :func:`characterise_arrays`).

    Without a time column (``time=None`` or ``""``) the sample interval must be given;
    ``time_unit`` (s, ms, us, min) overrides the unit read from the time column's header;
    ``window`` (start, end) in seconds reads only those rows; ``missing`` "bridge" drops and
    bridges rows with a missing reading (default "refuse": an input error).
    """
    if sensor1 == sensor2:
        raise InputError(f"--sensor1 and --sensor2 name the same column {sensor1!r}")
    if flow is not None and flow in (sensor1, sensor2):
        raise InputError(f"--flow {flow!r} names a sensor column")
    wanted = [sensor1, sensor2] + ([reference] if reference else []) + ([flow] if flow else [])
    # the flow and the reference are not readings to bridge: a missing value there is refused
    recording = load_pair(
        path, wanted, time=time, time_unit=time_unit, sample_interval=sample_interval,
        required=[name for name in (reference, flow) if name], window=window,
        missing=missing,
    )
    if flow:
        recording.require_positive(flow, f"--flow {flow!r} must be > 0 (any positive "
                                   "flow-like quantity: only its ratios matter)")
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
        flow=columns[flow] if flow else None,
        flow_column=flow,
        track=track,
        uncertainty=uncertainty,
    )
    return replace(result, notes=recording.notes + result.notes)


def write_json(result: Characterisation, path: str | os.PathLike[str]) -> None:
    """Write the `--json` document (strict JSON: non-finite numbers become null)."""
    write_json_document(result.to_json_dict(), path)


def write_reconstruction(result: Characterisation, path: str | os.PathLike[str]) -> None:
    """Write the `--output` CSV: `t,T_g_hat,T_g_std,tau1,tau2`, one row per input row (`nan`
    where no value): the reconstruction, its standard deviation (the smoother's posterior, or
    the causal filter's own variance, given the model) and each sensor's dominant time
    constant in effect at the row."""
    if result.gas_estimate is None:
        raise InputError("no reconstruction to write")
    tau1, tau2 = result.time_constants_per_row()
    std = result.gas_std if result.gas_std is not None else np.full(result.time.size, np.nan)
    write_columns(path, {"t": result.time, "T_g_hat": result.gas_estimate, "T_g_std": std,
                         "tau1": tau1, "tau2": tau2})
