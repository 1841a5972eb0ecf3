"""The result of a pair characterisation (:class:`PairEstimate`), whatever method made it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dualprobe.estimation.confidence import Confidence
    from dualprobe.estimation.field import FlowModel

__all__ = [
    "PairEstimate",
]


@dataclass(frozen=True)
class PairEstimate:
    """Characterisation of a sensor pair; time constants in seconds, per sensor largest first.

    ``status``: ok | insufficient_excitation | infeasible (| invalid_argument from the core).
    ``details`` holds the numbers behind the estimate (filter time constant, eigenvalues,
    the core's fit, ...) and ``message`` when the status is not ok. With a flow law or
    tracking the time constants are those at psi = 1 (the reference flow) and
    ``flow_model.psi`` schedules them per sample (tau / psi).
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
    flow_model: FlowModel | None = None  # how the time constants vary: a flow law or tracked
    confidence: Confidence | None = None  # standard uncertainties and identifiability

    @property
    def stage_on_each(self) -> bool:
        """Order 2 with a second stage on each sensor (their common part cancels from the
        cross-relation)."""
        return self.order == 2 and all(len(taus) == 2 for taus in self.time_constants)
