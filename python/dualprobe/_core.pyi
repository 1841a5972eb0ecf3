"""Type stubs of the C++ core bindings (bindings/module.cpp)."""

from typing import Any

import numpy as np
import numpy.typing as npt

_Array = npt.NDArray[np.float64] | npt.NDArray[np.float32]

class _DifferenceEstimatorBase:
    def __init__(
        self,
        ts: float,
        method: str = "gtls",
        sigma1: float = 0.0,
        sigma2: float = 0.0,
        forgetting: float = 1.0,
    ) -> None: ...
    def update(self, t1: float, t2: float) -> str: ...
    def update_batch(self, t1: _Array, t2: _Array) -> int: ...
    def solve(self) -> dict[str, Any]: ...
    def reset(self) -> None: ...
    def break_chain(self) -> None: ...
    @property
    def rows(self) -> float: ...
    @property
    def scatter(self) -> npt.NDArray[np.float64]: ...

class DifferenceEstimator(_DifferenceEstimatorBase): ...
class DifferenceEstimatorF(_DifferenceEstimatorBase): ...

def estimate_difference(
    t1: _Array,
    t2: _Array,
    ts: float,
    method: str = "gtls",
    sigma1: float = 0.0,
    sigma2: float = 0.0,
    forgetting: float = 1.0,
) -> dict[str, Any]: ...
def reconstruct_inverse(temps: _Array, tau: float, ts: float) -> _Array: ...
def simulate_hysteretic_first_order(
    tg: _Array, ts: float, tau_heat: float, tau_cool: float, initial: float
) -> _Array: ...
