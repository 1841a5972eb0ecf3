"""The result of a pair characterisation (:class:`PairEstimate`), whatever method made it."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "PairEstimate",
]


@dataclass(frozen=True)
class PairEstimate:
    """Characterisation of a sensor pair; time constants in seconds, per sensor largest first.

    ``status``: ok | insufficient_excitation | infeasible (| invalid_argument from the core).
    ``details`` holds the numbers behind the estimate (filter time constant, eigenvalues,
    ...) and ``message`` when the status is not ok.
    """

    status: str
    method: str
    order: int
    sample_interval: float
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    beta: float | None
    noise_std: tuple[float, float]
    time_constants_heat: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    time_constants_cool: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    identifiability: dict[str, object] = field(default_factory=dict)
    details: dict[str, object] = field(default_factory=dict)
