"""``characterise_pair``: what ``dualprobe characterise`` calls. Checks the signals, estimates
the noise levels unless given, and runs the SVF (:mod:`dualprobe.estimation.svf`, the default
``method="auto"``) or the paper's difference method (:mod:`dualprobe.estimation.difference`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from dualprobe.estimation.confidence import confidence
from dualprobe.estimation.difference import characterise_difference
from dualprobe.estimation.engine import STATIC_MODELS
from dualprobe.estimation.field import FlowModel, RunSvf
from dualprobe.estimation.flow import FlowSignal, check_flow, evidence
from dualprobe.estimation.flow_noise import column_noise, noise_evidence
from dualprobe.estimation.flow_split import split_evidence
from dualprobe.estimation.flow_timing import shifted, timed_flow_law, unheld
from dualprobe.estimation.relevel import relevel
from dualprobe.estimation.result import PairEstimate
from dualprobe.estimation.settings import GAP_THRESHOLD
from dualprobe.estimation.svf import characterise_svf
from dualprobe.estimation.without_flow import track_without_flow
from dualprobe.io import InputError
from dualprobe.models.noise import ORDER_ESTIMATION, estimate_noise_std

__all__ = ["METHODS", "TRACKING", "characterise_pair", "has_level_term", "relevelled"]


METHODS = ("auto", "svf", "ls", "tls", "gtls")
TRACKING = ("auto", "off")
_MIN_SAMPLES = 20


def _check_inputs(
    t1: np.ndarray, t2: np.ndarray, ts: float, method: str, order: int, hysteresis: bool
) -> tuple[np.ndarray, np.ndarray, float]:
    a = np.asarray(t1, dtype=float)
    b = np.asarray(t2, dtype=float)
    if a.ndim != 1 or a.shape != b.shape:
        raise InputError(f"characterise_pair: t1 and t2 must be 1-D of equal length, got {a.shape} "
                         f"and {b.shape}")
    for name, x in (("t1", a), ("t2", b)):
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise InputError(f"characterise_pair: {name}[{int(bad[0])}] is not finite")
    try:
        ts = float(ts)
    except (TypeError, ValueError):
        raise InputError(
            f"characterise_pair: sample interval must be a number, got {ts!r}") from None
    if not (math.isfinite(ts) and ts > 0.0):
        raise InputError(f"characterise_pair: sample interval must be finite and > 0, got {ts!r}")
    if method not in METHODS:
        raise InputError(f"characterise_pair: method must be one of {', '.join(METHODS)}, "
                         f"got {method!r}")
    if order not in (1, 2):
        raise InputError(f"characterise_pair: order must be 1 or 2, got {order!r}")
    if method in ("ls", "tls", "gtls") and (order != 1 or hysteresis):
        raise InputError(f"characterise_pair: method {method!r} (difference equation) is first "
                         "order without hysteresis; use method 'auto' for order 2 or hysteresis")
    if hysteresis and order != 1:
        raise InputError("characterise_pair: the hysteresis-aware estimate is first order; "
                         "use order=1 with hysteresis=True")
    return a, b, ts


def _noise_levels(
    t1: np.ndarray, t2: np.ndarray, noise_std: float | Sequence[float] | None
) -> tuple[tuple[float, float], str]:
    if noise_std is None:
        levels = tuple(estimate_noise_std(x, ORDER_ESTIMATION) for x in (t1, t2))
        return (levels[0], levels[1]), "estimated"
    values = np.atleast_1d(np.asarray(noise_std, dtype=float)).ravel()
    if values.size == 1:
        values = np.repeat(values, 2)
    if values.size != 2 or not np.all(np.isfinite(values)) or np.any(values < 0.0):
        raise InputError(f"characterise_pair: noise_std must be one or two finite values >= 0, "
                         f"got {noise_std!r}")
    return (float(values[0]), float(values[1])), "given"


PRACTICAL_HYSTERESIS = 0.05  # heating and cooling time constants must differ by >= 5 %


def _hysteresis_beyond_flow(split: PairEstimate, unsplit: PairEstimate) -> PairEstimate:
    """Keep the heating/cooling split only when it explains significantly more than the same
    flow law without it and the time constants differ in practice: with the gas heating at
    high load (high flow, short time constants) and cooling at low load, flow dependence looks
    like hysteresis to a model without the flow."""
    if unsplit.status != "ok" or split.time_constants_heat is None:
        return split
    heat, cool = split.time_constants_heat, split.time_constants_cool
    assert cool is not None
    differ = max(abs(heat[i][0] / cool[i][0] - 1.0) for i in range(2))
    n_eff = float(unsplit.details.get("effective_samples", 0.0))  # type: ignore[arg-type]
    statistic = evidence(float(unsplit.details["residual_to_noise"]),  # type: ignore[arg-type]
                         float(split.details["residual_to_noise"]), n_eff)  # type: ignore[arg-type]
    if statistic > GAP_THRESHOLD and differ > PRACTICAL_HYSTERESIS:
        split.details["hysteresis_statistic"] = statistic
        return split
    notes = list(unsplit.identifiability.get("notes", []))  # type: ignore[call-overload]
    notes.append(f"no heating/cooling difference beyond the flow dependence (statistic "
                 f"{statistic:.3g} < {GAP_THRESHOLD:g} or time constants within "
                 f"{PRACTICAL_HYSTERESIS:.0%}): reported without hysteresis")
    unsplit.identifiability["notes"] = notes
    unsplit.details["hysteresis_statistic"] = statistic
    return unsplit


def _misfits(estimate: PairEstimate) -> bool:
    """The estimate's misfit lies beyond ``GAP_THRESHOLD`` noise standard deviations."""
    mu = float(estimate.details.get("residual_to_noise", 1.0))  # type: ignore[arg-type]
    n_eff = float(estimate.details.get("effective_samples", 0.0))  # type: ignore[arg-type]
    return evidence(mu, 1.0, n_eff) > GAP_THRESHOLD


def characterise_pair(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    method: str = "auto",
    order: int = 1,
    hysteresis: bool = False,
    noise_std: float | Sequence[float] | None = None,
    filter_time_constant: float | None = None,
    static_model: str = "auto",
    flow: np.ndarray | None = None,
    flow_column: str | None = None,
    track: str = "off",
    uncertainty: bool = False,
) -> PairEstimate:
    """Identify the two sensors' time constants from their signals alone.

    ``method``: auto | svf (state-variable filter, design.md 1.4; auto = svf with the filter
    time constant chosen from the data) or ls | tls | gtls (the paper's difference method,
    first order only). ``noise_std``: white-noise standard deviation, one value or one per
    sensor; estimated from the signals when None. ``filter_time_constant``: the SVF's tf in
    seconds (None: automatic). ``static_model`` (SVF): "unit" (both sensors of unit static
    gain, design.md 1.4), "affine" (a gain ratio and an offset between the sensors are
    estimated too; reported in ``details``) or "auto" (affine only when it fits significantly
    better). ``flow`` (N,): a positive flow-like signal; the time constants then follow a flow
    law chosen by evidence (constant, power law or curve: :mod:`dualprobe.estimation.field`),
    at the median flow in ``time_constants``. ``track="auto"``: without a flow, track a common
    time variation of both time constants when the constant model misfits and tracking
    explains it. ``uncertainty``: standard uncertainties and identifiability
    (:mod:`dualprobe.estimation.confidence`) in ``confidence``. Raises ValueError
    (dualprobe.io.InputError) for bad arguments; estimation failures are reported in
    ``status`` with ``details["message"]``.
    """
    a, b, ts = _check_inputs(t1, t2, ts, method, order, hysteresis)
    if filter_time_constant is not None and not (
        math.isfinite(filter_time_constant) and filter_time_constant > 0.0
    ):
        raise InputError(f"characterise_pair: filter_time_constant must be finite and > 0, "
                         f"got {filter_time_constant!r}")
    sigma, source = _noise_levels(a, b, noise_std) if a.size >= ORDER_ESTIMATION + 2 else (
        (0.0, 0.0), "too few samples")
    if a.size < _MIN_SAMPLES:
        return PairEstimate(
            status="insufficient_excitation", method=method, order=order, sample_interval=ts,
            time_constants=((float("nan"),) * order,) * 2, beta=None, noise_std=sigma,
            details={"message": f"{a.size} samples: at least {_MIN_SAMPLES} are needed"},
        )
    if method in ("ls", "tls", "gtls"):
        return characterise_difference(a, b, ts, method, sigma, source)
    if static_model not in ("auto", *STATIC_MODELS):
        raise InputError(f"characterise_pair: static_model must be auto, unit or affine, "
                         f"got {static_model!r}")
    if track not in TRACKING:
        raise InputError(f"characterise_pair: track must be one of {', '.join(TRACKING)}, "
                         f"got {track!r}")
    signal = None
    if flow is not None:
        try:
            signal = check_flow(flow, flow_column, a.size)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        column = signal.values  # as logged: its noise is measured on it (flow_noise)
    run = _runner(a, b, ts, order, hysteresis, sigma, source, filter_time_constant,
                  static_model, flow is not None)
    base = run(None)
    model = None
    estimate = base
    if signal is not None or track == "auto":
        # The flow law and the tracking start from a first-order fit: with time constants
        # that vary, a constant second-order model is no anchor (it absorbs the variation in
        # spurious poles); the order is chosen again with the schedule found.
        first = base if order == 1 else run(None, 1)
        if first.status != "ok":
            return base
        if signal is not None:
            estimate, model, signal = timed_flow_law(a, b, first, signal, run)
            signal = _with_level(model, signal)
        elif base.status != "ok" or _misfits(base):
            estimate, model = track_without_flow(a, b, first, run)
        if model is not None and model.kind == "constant":
            estimate = base
        if base.status != "ok" and estimate is base:
            return base
        if signal is not None and hysteresis and model is not None and model.scheduled:
            tf = float(estimate.details["filter_time_constant"])  # type: ignore[arg-type]
            estimate = _hysteresis_beyond_flow(
                estimate, characterise_svf(a, b, ts, 1, False, sigma, source, tf,
                                           static_model, schedule=model.psi))
        if signal is not None and model is not None and estimate.status == "ok":
            model.evidence.update(noise_evidence(a, b, estimate, model,
                                                 column_noise(column, ts)))
            model.evidence.update(split_evidence(a, b, estimate, model))
    elif base.status != "ok":
        return base
    conf = confidence(a, b, estimate, model or FlowModel("constant", np.ones(a.size)), signal) \
        if uncertainty else None
    return dataclasses.replace(estimate, flow_model=model, confidence=conf)


def _runner(a: np.ndarray, b: np.ndarray, ts: float, order: int, hysteresis: bool,
            sigma: tuple[float, float], source: str, filter_time_constant: float | None,
            static_model: str, flow_given: bool = False) -> RunSvf:
    """The SVF characterisation on a schedule psi (None: constant), at ``order`` or
    ``fit_order``, with these settings."""
    def run(psi: np.ndarray | None, fit_order: int = order) -> PairEstimate:
        return characterise_svf(a, b, ts, fit_order, hysteresis, sigma, source,
                                filter_time_constant, static_model, schedule=psi,
                                flow_given=flow_given)

    return run


def _with_level(model: FlowModel, signal: FlowSignal) -> FlowSignal:
    """``signal`` with the level term's per-row factor as fitted (the exponent's uncertainty
    is then that of the law with its level term), where the law has one."""
    if model.level_reference is None:
        return signal
    return dataclasses.replace(signal, factor=model.psi / signal.psi(model.exponent))


def has_level_term(estimate: PairEstimate) -> bool:
    """Whether ``estimate``'s flow law carries a gas-level term that :func:`relevelled` can
    search again (an SVF fit with the flow)."""
    model = estimate.flow_model
    return (model is not None and model.level_reference is not None
            and estimate.method in ("auto", "svf"))


def relevelled(t1: np.ndarray, t2: np.ndarray, ts: float, estimate: PairEstimate,
               gas: np.ndarray, *, flow: np.ndarray, flow_column: str | None,
               noise_std: float | Sequence[float] | None = None,
               uncertainty: bool = False) -> PairEstimate | None:
    """``estimate`` (from :func:`characterise_pair` with ``flow``, the same signals and noise
    levels, the default filter and static settings) with its flow law's level term searched
    again with ``gas`` (its reconstruction, in sensor 1's unit) as the level
    (:func:`dualprobe.estimation.relevel.relevel`), or None where that is not better. The flow
    is taken as the law saw it: held values interpolated, shifted by the law's delay."""
    model = estimate.flow_model
    if model is None or not has_level_term(estimate):
        return None
    a, b, ts = _check_inputs(t1, t2, ts, estimate.method, estimate.order, False)
    sigma, source = _noise_levels(a, b, noise_std)
    try:
        signal = check_flow(flow, flow_column, a.size)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    signal = shifted(unheld(signal, ts)[0], model.delay, ts)
    run = _runner(a, b, ts, estimate.order, False, sigma, source, None, "auto", True)
    again = relevel(a, b, estimate, signal, run, gas)
    if again is None or again.flow_model is None:
        return None
    # the regimes judged on the law as it now is (a sheathed pair's pre-relevel law misfit the
    # high-flow half at 1.58, the relevelled one at 1.03)
    again.flow_model.evidence.update(split_evidence(a, b, again, again.flow_model))
    conf = (confidence(a, b, again, again.flow_model, _with_level(again.flow_model, signal))
            if uncertainty else None)
    return dataclasses.replace(again, confidence=conf)
