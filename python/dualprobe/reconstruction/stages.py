"""The sensor stages the samples resolve: a stage far faster than the sample interval is merged
(see :mod:`dualprobe.reconstruction`, "Fast stages")."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["STAGE_MERGE_FRACTION", "resolvable_stages", "unresolved_lag"]

STAGE_MERGE_FRACTION = 0.05  # stages faster than Ts/20 are merged (see the package docstring)


def resolvable_stages(
    taus: Sequence[float], ts: float, taus_cool: Sequence[float] | None = None
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The stages of one sensor as the model-based modes (smoother, filter) use them.

    A second stage faster than ``STAGE_MERGE_FRACTION * ts`` (heating or cooling) is merged
    into the other one with the sum of the time constants kept (the lag on a ramp, i.e. the
    first moment of the impulse response); a remaining single stage faster than that limit
    is raised to it. Returns (heating, cooling) time constants, cooling = heating when
    ``taus_cool`` is None. See the module docstring for why and what it costs.
    """
    heat = tuple(float(t) for t in taus)
    cool = heat if taus_cool is None else tuple(float(t) for t in taus_cool)
    if len(cool) != len(heat):
        raise ValueError(
            f"resolvable_stages: need as many cooling as heating time constants, got "
            f"{len(cool)} and {len(heat)}"
        )
    limit = STAGE_MERGE_FRACTION * float(ts)
    if len(heat) == 2 and min(heat + cool) < limit:
        heat, cool = (heat[0] + heat[1],), (cool[0] + cool[1],)
    return tuple(max(t, limit) for t in heat), tuple(max(t, limit) for t in cool)


def unresolved_lag(
    taus: Sequence[float], taus_cool: Sequence[float] | None, ts: float
) -> float:
    """Seconds of lag :func:`resolvable_stages` leaves unmodelled (the largest over heating
    and cooling): a merged stage's time constant, or what a single stage was raised by."""
    lags = []
    for given in (tuple(taus), tuple(taus_cool) if taus_cool is not None else tuple(taus)):
        heat, _ = resolvable_stages(given, ts)
        merged = min(given) if len(heat) < len(given) else 0.0
        lags.append(merged + abs(sum(heat) - sum(given)))
    return max(lags)
