"""The order chosen by evidence (``--order auto``): when an order-2 fit's stages are model
error absorbed rather than resolved stages, first order instead, with the reason recorded in
the identifiability notes; and, with order 2 asked for, no number where its stages are not
what the data say."""

from __future__ import annotations

import math
from dataclasses import replace

from dualprobe.estimation import PairEstimate
from dualprobe.io import EstimationError
from dualprobe.workflows.checks import (
    describe_stages,
    regime_shared_stage,
    spurious_shared_stage,
    undetermined_gain,
    undetermined_stages,
    unsettled_stages,
)

__all__ = ["common_lag_note", "first_order", "first_order_reason", "refuse_regimes",
           "regimes_reason"]

_COMMON = (": model error absorbed by a stage nearly common to both sensors, e.g. sheaths that "
           "follow the flow with their own exponents, or time constants that also follow the "
           "gas temperature")


def first_order_reason(estimate: PairEstimate, columns: tuple[str, str]) -> str | None:
    """Why an order-2 fit is no resolved model (None where it is): a second stage that the
    filter setting moves (in a model that claims to explain the data), one shared by both
    sensors (misfitting or not determined), a gain ratio or time constants the data do not
    determine."""
    if estimate.status != "ok":
        return None
    unsettled = unsettled_stages(estimate)
    if unsettled:
        return ("the second-order fit's second time constant of "
                + " and of ".join(f"{columns[i]} ({share:.0%})" for i, share in unsettled)
                + " depends on the filter time constant (standard uncertainty from it alone; "
                "a resolved stage: under 5 %)" + _COMMON)
    shared = spurious_shared_stage(estimate)
    if shared is not None:
        return (f"the second-order fit gave both sensors a time constant of about "
                f"{shared[0]:.3g} / {shared[1]:.3g} s, which a pair cannot determine" + _COMMON)
    gain = undetermined_gain(estimate)
    if gain is not None:
        # a NaN ratio (no finite estimate) is named as such, not printed as "nan"
        value = f"{gain:.3g}" if math.isfinite(gain) else "no finite value"
        return (f"the second-order fit's gain ratio ({value}) is not determined by the data: "
                "its second stages and static map trade against each other")
    loose = undetermined_stages(estimate)
    if loose:
        return ("the second-order fit's time constants " + describe_stages(loose, columns)
                + " are not determined by the data: its stages trade against each other, as "
                "when both sensors have nearly equal second stages")
    return None


def regimes_reason(estimate: PairEstimate) -> str | None:
    """Why an order-2 flow law's near-equal stages are no resolved pair (None where they
    may be): they explain the low-flow and high-flow halves unalike
    (:func:`~dualprobe.workflows.checks.regime_shared_stage`)."""
    shared = regime_shared_stage(estimate)
    if shared is None or estimate.flow_model is None:
        return None
    regimes = estimate.flow_model.evidence["flow_split_statistic"]
    return (f"the second-order fit's nearly equal stages of {shared[0]:.3g} / {shared[1]:.3g} s "
            f"explain the record's low-flow and high-flow halves unalike ({regimes:.0f} "
            "standard deviations apart): the common part of two near-equal stages is fixed "
            "only through the flow law's exact shape and takes up its error, so the pair does "
            "not determine it")


def common_lag_note(estimate: PairEstimate) -> str | None:
    """What a first-order pair's time constants are, or an order-2 pair's with a second stage on
    one sensor only (None where both have one): two signals determine at most their
    difference, never a lag common to both sensors. Sheaths on both sensors that the
    data do not resolve act, to second order in the frequency, as such a common lag: the
    first-order fit gives both sensors' total lags (the sum of each one's stages) short by one
    amount, delta = (b s2 - a s1) / (b + s2 - a - s1) for elements a, b behind sheaths s1, s2.
    Measured on the separate generator (120 s at idle, 50 Hz, 0.71 / 2.0 s elements): sheaths of
    0.23 / 0.5 s gave 0.335 / 1.874 s (both totals 0.61 / 0.63 s short), 0.15 / 0.8 s gave 0.12
    / 2.10 s (0.74 / 0.70 s short), 0.3 / 0.3 s the elements, each within 1.2 times the noise;
    on four sheathed drive-cycle pairs with the gas velocity, 0.53 / 0.50, 0.39 / 0.42, 0.56 /
    0.57 and 0.47 / 0.47 s short. Tracked without the flow the schedule's error adds (the same
    pairs: total over estimate 1.86 / 1.63, 2.16 / 2.05)."""
    if estimate.status != "ok":
        return None
    orders = [len(taus) for taus in estimate.time_constants]
    tracked = estimate.flow_model is not None and estimate.flow_model.kind == "tracked"
    tail = (("; tracked without the flow, the schedule's own error comes on top" if tracked
             else "") + "; the sheaths' datasheet tells")
    if estimate.order == 2 and sorted(orders) == [1, 2]:
        # one sensor's second stage only: sheaths on both show as one stage, their
        # difference (logger_sweep.py 133 8: 0.61 / 0.85 s sheaths gave one 0.14 s stage,
        # the gas 0.22 s late and 2.54x the oracle; 1.00 / 0.68 s one 0.16 s, 0.35 s late)
        lone = max(taus[-1] for taus in estimate.time_constants if len(taus) == 2)
        return (f"one sensor's second stage only ({lone:.3g} s): two signals determine the "
                "stages' differences, never a lag common to both sensors: sheaths on both "
                "show as one stage, their difference, and lengthen both sensors' total lag by "
                "one unseen amount, by which the gas is late" + tail)
    if estimate.order != 1:
        return None
    fast, slow = (taus[0] for taus in estimate.time_constants)
    return (f"first order: two signals determine at most the time constants' difference "
            f"({abs(slow - fast):.3g} s), never a lag common to both sensors: sheaths on both that "
            "these data do not resolve lengthen both sensors' total lag (the sum of its "
            "stages) by one unseen amount (0.23 / 0.5 s sheaths on 0.71 / 2.0 s elements gave "
            "0.335 / 1.874 s)" + tail)


def first_order(first: PairEstimate, why: str) -> PairEstimate:
    """The first-order estimate with the reason it replaces order 2 recorded."""
    ident = dict(first.identifiability)
    ident["order_fallback"] = "order chosen by evidence: first order; " + why
    return replace(first, identifiability=ident)


def refuse_regimes(estimate: PairEstimate) -> None:
    """Raise EstimationError (exit 3) for an asked-for order 2 whose near-equal stages explain
    low and high flow unalike (:func:`regimes_reason`): no sheath is identified there, and the
    gas it gives was 4.8-11.7 times the error possible."""
    why = regimes_reason(estimate)
    if why is not None:
        raise EstimationError(why + "; use the order chosen by evidence (--order auto) or "
                              "--order 1")
