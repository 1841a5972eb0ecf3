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

# Streaming state-variable-filter estimator (svf_estimator.hpp; bindings/svf.cpp).
class _SvfEstimatorBase:
    def __init__(
        self,
        ts: float,
        tf: float,
        order: int = 1,
        static: str = "unit",
        hysteresis: bool = False,
        sigma1: float = 0.0,
        sigma2: float = 0.0,
        forgetting: float = 1.0,
        direction_half_window: int | None = None,
        dead_zone: float = 2.0,
    ) -> None: ...
    def update(self, t1: float, t2: float) -> str: ...
    def update_batch(self, t1: _Array, t2: _Array) -> int: ...
    def solve(self) -> dict[str, Any]: ...
    def reset(self) -> None: ...

class SvfEstimator(_SvfEstimatorBase): ...
class SvfEstimatorF(_SvfEstimatorBase): ...

def estimate_svf(
    t1: _Array,
    t2: _Array,
    ts: float,
    tf: float,
    order: int = 1,
    static: str = "unit",
    hysteresis: bool = False,
    sigma1: float = 0.0,
    sigma2: float = 0.0,
    forgetting: float = 1.0,
    direction_half_window: int | None = None,
    dead_zone: float = 2.0,
) -> dict[str, Any]: ...

# Causal Kalman reconstruction with jump detection (kalman.hpp; bindings/kalman.cpp).
class _KalmanReconstructorBase:
    def __init__(
        self,
        ts: float,
        taus1: Any,
        taus2: Any,
        sigma: Any,
        q: float,
        *,
        gas: str = "rw",
        taus1_cool: Any = None,
        taus2_cool: Any = None,
        detect_jumps: bool = True,
        window: int = 64,
        false_alarm: float = 1e-6,
    ) -> None: ...
    def update(self, t1: float, t2: float) -> str: ...
    def skip(self) -> str: ...
    def update_batch(self, t1: _Array, t2: _Array) -> _Array: ...
    def reset(self) -> None: ...
    @property
    def gas(self) -> float: ...
    @property
    def gas_variance(self) -> float: ...

class KalmanReconstructor(_KalmanReconstructorBase): ...
class KalmanReconstructorF(_KalmanReconstructorBase): ...

def kalman_filter(
    t1: Any,
    t2: Any,
    ts: float,
    taus1: Any,
    taus2: Any,
    sigma: Any,
    q: float,
    *,
    gas: str = "rw",
    taus1_cool: Any = None,
    taus2_cool: Any = None,
    detect_jumps: bool = True,
    window: int = 64,
    false_alarm: float = 1e-6,
) -> Any: ...
