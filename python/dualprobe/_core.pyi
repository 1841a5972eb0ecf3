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

# Streaming state-variable-filter estimator, optionally flow-scheduled (svf_estimator.hpp;
# bindings/svf.cpp, svf_handle.hpp, svf_schedule1.cpp, svf_schedule2.cpp; design.md 1.4, 1.5).
class _SvfEstimatorBase:
    max_half_window: int  # class attribute: 1024
    max_basis: int  # class attribute: 8
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
        direction_half_window: int | tuple[int, int] | None = None,
        dead_zone: float = 2.0,
        basis: int = 0,
    ) -> None: ...
    def update(
        self,
        t1: float,
        t2: float,
        schedule: float | list[float] | None = None,
        phi: float | None = None,
    ) -> str: ...
    def update_batch(
        self,
        t1: _Array,
        t2: _Array,
        schedule: _Array | None = None,
        phi: _Array | None = None,
    ) -> int: ...
    def solve(self) -> dict[str, Any]: ...
    def solve_moments(
        self, moments: npt.ArrayLike, offsets: tuple[float, float] | None = None
    ) -> dict[str, Any]: ...
    def moments(self) -> npt.NDArray[np.float64]: ...
    def accumulated_moments(self) -> npt.NDArray[np.float64]: ...
    def reset(self) -> None: ...
    @property
    def rows(self) -> float: ...
    @property
    def samples(self) -> int: ...
    @property
    def basis(self) -> int: ...
    @property
    def offsets(self) -> tuple[float, float]: ...
    @property
    def scatter(self) -> npt.NDArray[np.float64]: ...
    @property
    def noise_covariance(self) -> npt.NDArray[np.float64]: ...
    @property
    def accumulated_noise_covariance(self) -> npt.NDArray[np.float64]: ...
    @property
    def omega_moments(self) -> npt.NDArray[np.float64]: ...
    @property
    def moment_layout(self) -> dict[str, slice]: ...
    @property
    def nbytes(self) -> int: ...

class SvfEstimator(_SvfEstimatorBase): ...
class SvfEstimatorF(_SvfEstimatorBase): ...

# Returns: status, order, static, hysteresis, basis, filter_time_constant, theta, polynomials,
# time_constants, time_constants_heat, time_constants_cool, gain_ratio, offset, eigenvalues,
# eigenvalue_ratio, rows, refused, precision, moments, moment_layout, omega_moments, offsets;
# with block_length > 0 also block_moments (B, L) and block_length.
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
    direction_half_window: int | tuple[int, int] | None = None,
    dead_zone: float = 2.0,
    schedule: _Array | None = None,
    phi: _Array | None = None,
    block_length: int = 0,
) -> dict[str, Any]: ...

def solve_svf_moments(
    moments: npt.ArrayLike,
    ts: float,
    tf: float,
    order: int = 1,
    static: str = "unit",
    hysteresis: bool = False,
    sigma1: float = 0.0,
    sigma2: float = 0.0,
    basis: int = 0,
    offsets: tuple[float, float] = (0.0, 0.0),
    precision: str = "float64",
) -> dict[str, Any]: ...

# Per-interval exact discretisation of the pair model (bindings/intervals.cpp).
def discretise_intervals(
    taus1: npt.ArrayLike, taus2: npt.ArrayLike, ts: float, gas: str = "rw"
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...

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
