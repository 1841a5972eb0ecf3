"""Transfer-function identification from a reference measurement to a sensor output.

What MATLAB's ``tfest`` / ``compare`` give, for the models of the paper's Tables I and II:

* order 1: ``K / (1 + tau s)``
* order 2: ``K / ((1 + tau_a s)(1 + tau_b s))`` (``tau_a >= tau_b``)

each optionally with a dead time ``exp(-theta s)``.

Method: output-error fitting. The continuous model is discretised *exactly* for an input that
is linear between samples (first-order hold, the default: a measured reference temperature is
smooth) or constant between samples (zero-order hold); a fractional dead time is handled
exactly by splitting the sample interval at the delayed sample instant. The discrete model is
simulated with :func:`scipy.signal.lfilter`. The initial state is estimated (one value per
state, in output units), not assumed zero. The gain and the initial state enter linearly, so
the search over the time constants and the dead time uses variable projection (the linear
parameters are solved for at every trial) from a coarse multi-start grid; the best candidate is
then polished with :func:`scipy.optimize.least_squares` over all parameters.

Uncertainties are the usual 1-sigma values ``sqrt(diag(s^2 (J^T J)^-1))`` with ``J`` the
Jacobian of the simulated output with respect to the reported parameters and ``s^2`` the
residual variance. They assume white residuals; with autocorrelated residuals (model error,
coloured noise) they are optimistic, which is why the lag-1 autocorrelation of the residuals
is reported alongside.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from scipy import linalg, optimize, signal

from dualprobe.io import EstimationError

__all__ = [
    "HOLDS",
    "INITIAL_CONDITIONS",
    "IdentificationError",
    "TfFit",
    "fit_transfer_function",
    "simulate_fit",
    "simulate_model",
]

HOLDS = ("foh", "zoh")
INITIAL_CONDITIONS = ("estimate", "steady")
Hold = Literal["foh", "zoh"]
Initial = Literal["estimate", "steady"]

# Relative tolerance on the regularity of a time vector (same as dualprobe.io).
_IRREGULAR_TIME_TOLERANCE = 1e-6


class IdentificationError(EstimationError):
    """The data are valid but no model can be fitted (e.g. a constant input)."""


@dataclass(frozen=True)
class TfFit:
    """Result of :func:`fit_transfer_function`.

    ``taus`` are ordered largest first; ``*_std`` are 1-sigma uncertainties (white-residual
    assumption, see the module docstring). ``initial_state`` is the model state at the first
    sample in output units (first entry = the model output at the first sample).
    """

    order: int
    gain: float
    gain_std: float
    taus: tuple[float, ...]
    taus_std: tuple[float, ...]
    delay: float
    delay_std: float
    delay_estimated: bool
    initial_state: tuple[float, ...]
    initial_state_std: tuple[float, ...]
    sample_interval: float
    n_samples: int
    n_parameters: int
    rmse: float
    fit_percent: float
    aic: float
    aicc: float
    bic: float
    residual_autocorrelation: float
    input_noise_std: float
    hold: str
    initial: str
    parameter_names: tuple[str, ...]
    covariance: tuple[tuple[float, ...], ...]
    n_function_evaluations: int

    @property
    def model(self) -> str:
        """The fitted transfer function as text, e.g. ``0.99/((1+0.17s)(1+12.3s))``."""
        poles = "".join(f"(1+{tau:.4g}s)" for tau in sorted(self.taus))
        text = f"{self.gain:.4g}/{poles}" if len(self.taus) == 1 else f"{self.gain:.4g}/({poles})"
        if self.delay_estimated:
            text += f"*exp(-{self.delay:.4g}s)"
        return text

    def summary(self) -> str:
        """A short human-readable report."""
        lines = [f"model  {self.model}"]
        lines.append(f"  gain K      = {self.gain:.6g} +/- {self.gain_std:.2g}")
        names = ["tau"] if self.order == 1 else ["tau_a", "tau_b"]
        for name, value, std in zip(names, self.taus, self.taus_std, strict=True):
            lines.append(f"  {name:<11} = {value:.6g} +/- {std:.2g} s")
        if self.delay_estimated:
            lines.append(f"  delay       = {self.delay:.6g} +/- {self.delay_std:.2g} s")
        lines.append(
            f"fit {self.fit_percent:.2f} % (NRMSE)   RMSE {self.rmse:.4g}   "
            f"AICc {self.aicc:.6g}   BIC {self.bic:.6g}"
        )
        lines.append(
            f"{self.n_samples} samples, Ts = {self.sample_interval:.6g} s, "
            f"{self.n_parameters} parameters, residual lag-1 autocorrelation "
            f"{self.residual_autocorrelation:.2f}"
            + (" (uncertainties optimistic)" if abs(self.residual_autocorrelation) > 0.3 else "")
        )
        if self.input_noise_std > 0:
            lines.append(f"input noise {self.input_noise_std:.3g} included in the uncertainties")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (plain floats, lists)."""
        return {
            "model": self.model,
            "order": self.order,
            "gain": self.gain,
            "gain_std": self.gain_std,
            "taus": list(self.taus),
            "taus_std": list(self.taus_std),
            "delay": self.delay,
            "delay_std": self.delay_std,
            "delay_estimated": self.delay_estimated,
            "initial_state": list(self.initial_state),
            "initial_state_std": list(self.initial_state_std),
            "sample_interval": self.sample_interval,
            "n_samples": self.n_samples,
            "n_parameters": self.n_parameters,
            "rmse": self.rmse,
            "fit_percent": self.fit_percent,
            "aic": self.aic,
            "aicc": self.aicc,
            "bic": self.bic,
            "residual_autocorrelation": self.residual_autocorrelation,
            "input_noise_std": self.input_noise_std,
            "hold": self.hold,
            "initial": self.initial,
            "parameter_names": list(self.parameter_names),
            "covariance": [list(row) for row in self.covariance],
        }


# --------------------------------------------------------------------------------------------
# Exact discretisation and simulation
# --------------------------------------------------------------------------------------------


def _cascade_state_space(taus: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit-gain cascade of first-order lags; the input enters the last lag, y = state 0.

    States are in output units: at rest every state equals the (unit-gain) input.
    """
    n = len(taus)
    a = np.zeros((n, n))
    b = np.zeros(n)
    for i, tau in enumerate(taus):
        a[i, i] = -1.0 / tau
        if i + 1 < n:
            a[i, i + 1] = 1.0 / tau
    b[n - 1] = 1.0 / taus[n - 1]
    c = np.zeros(n)
    c[0] = 1.0
    return a, b, c


def _phi_functions(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """phi1(z) = (e^z - 1)/z and phi2(z) = (e^z - 1 - z)/z^2, accurate for small |z|."""
    small = np.abs(z) < 1e-4
    safe = np.where(small, 1.0, z)
    phi1 = np.where(small, 1.0 + z / 2 + z * z / 6, np.expm1(safe) / safe)
    phi2 = np.where(small, 0.5 + z / 6 + z * z / 24, (np.expm1(safe) - safe) / (safe * safe))
    return phi1, phi2


def _segment(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State transition over a segment of length h with an input linear from v0 to v1.

    Returns (Phi, G0, G1) with x(h) = Phi x(0) + G0 v0 + G1 v1 (exact).
    """
    n = a.shape[0]
    if h <= 0.0:
        return np.eye(n), np.zeros(n), np.zeros(n)
    eigenvalues = np.diag(a)  # the cascade matrix is triangular
    if n == 1 or np.min(np.abs(np.diff(np.sort(eigenvalues)))) > 1e-6 * np.max(np.abs(eigenvalues)):
        # Modal form (distinct poles): e^{Ah} = V e^{Lh} V^-1 and the input integrals
        # int_0^h e^{A(h-s)} B ds = V h phi1(Lh) V^-1 B, int_0^h e^{A(h-s)} B s/h ds likewise
        # with phi2. Much cheaper than expm, which dominates the fit otherwise.
        _, vectors = linalg.eig(a)
        vectors = np.real(vectors)
        if np.linalg.cond(vectors) < 1e8:
            z = eigenvalues * h
            phi1, phi2 = _phi_functions(z)
            inverse = np.linalg.inv(vectors)
            vb = inverse @ b
            phi = (vectors * np.exp(z)) @ inverse
            g_const = vectors @ (h * phi1 * vb)
            g_ramp = vectors @ (h * phi2 * vb)
            return phi, g_const - g_ramp, g_ramp
    # Augmented system x' = A x + B w1, w1' = w2, w2' = 0 with w1(0) = v0, w2 = (v1 - v0) / h.
    m = np.zeros((n + 2, n + 2))
    m[:n, :n] = a
    m[:n, n] = b
    m[n, n + 1] = 1.0
    e = linalg.expm(m * h)
    phi = e[:n, :n]
    g_const = e[:n, n]
    g_ramp = e[:n, n + 1] / h
    return phi, g_const - g_ramp, g_ramp


def _charpoly(m: np.ndarray) -> np.ndarray:
    """Characteristic polynomial coefficients of a 1x1 or 2x2 matrix (highest power first)."""
    if m.shape[0] == 1:
        return np.array([1.0, -m[0, 0]])
    if m.shape[0] == 2:
        return np.array([1.0, -np.trace(m), m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]])
    return np.real(np.poly(m))


def _discretise(
    taus: Sequence[float], delay: float, ts: float, hold: str
) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """Exact discretisation of the unit-gain cascade with dead time.

    Returns (Phi, M, d, c) with x(k+1) = Phi x(k) + sum_j M[:, j] u(k - d - 1 + j), j = 0, 1, 2,
    y(k) = c x(k); d = floor(delay / ts).
    """
    a, b, c = _cascade_state_space(taus)
    n = a.shape[0]
    d = math.floor(delay / ts + 1e-12)
    phi_frac = delay - d * ts
    if phi_frac < 1e-12 * ts:
        phi_frac = 0.0
    r = phi_frac / ts
    coeff = np.zeros((n, 3))  # columns: u(k-d-1), u(k-d), u(k-d+1)
    # Segment 1: [t_k, t_k + phi_frac], delayed input from u(t_k - delay) to u(t_{k-d}).
    phi1, g10, g11 = _segment(a, b, phi_frac)
    # Segment 2: [t_k + phi_frac, t_{k+1}], delayed input from u(t_{k-d}) to u(t_{k+1} - delay).
    phi2, g20, g21 = _segment(a, b, ts - phi_frac)
    if hold == "foh":
        # Start of segment 1: r u(k-d-1) + (1 - r) u(k-d); end: u(k-d).
        seg1 = np.column_stack([r * g10, (1.0 - r) * g10 + g11, np.zeros(n)])
        # Segment 2: from u(k-d) to r u(k-d) + (1 - r) u(k-d+1).
        seg2 = np.column_stack([np.zeros(n), g20 + r * g21, (1.0 - r) * g21])
    else:
        # Piecewise constant: u(k-d-1) until the delayed sample instant, then u(k-d).
        seg1 = np.column_stack([g10 + g11, np.zeros(n), np.zeros(n)])
        seg2 = np.column_stack([np.zeros(n), g20 + g21, np.zeros(n)])
    coeff = phi2 @ seg1 + seg2
    return phi2 @ phi1, coeff, d, c


def _responses(
    taus: Sequence[float], delay: float, ts: float, hold: str, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Forced response of the unit-gain model to u (zero initial state) and free responses.

    Returns (forced, free) with free[:, i] = output for initial state e_i and zero input. Input
    samples before the record are taken equal to u[0] (the dead-time history).
    """
    phi, coeff, d, c = _discretise(taus, delay, ts, hold)
    n = phi.shape[0]
    size = u.size
    # Denominator from the (real, positive) eigenvalues exp(-ts/tau): no polynomial fitting.
    den = np.poly(np.exp(-ts / np.asarray(taus, dtype=float)))
    # Numerators of c (zI - Phi)^-1 g for each input column and each initial-state direction.
    columns = np.column_stack([coeff, np.eye(n)])
    # ss2tf's identity for D = 0: numerator = charpoly(Phi - g c) - charpoly(Phi).
    base_poly = _charpoly(phi)
    numerators = [
        _charpoly(phi - np.outer(columns[:, j], c)) - base_poly for j in range(columns.shape[1])
    ]
    forced = np.zeros(size)
    base = np.arange(size)
    for j in range(3):
        shifted = u[np.clip(base - d - 1 + j, 0, size - 1)]
        forced += signal.lfilter(numerators[j], den, shifted)
    # Free response y(k) = c Phi^k e_i = impulse response (input e_i) one step later.
    impulse = np.zeros(size + 1)
    impulse[0] = 1.0
    free = np.empty((size, n))
    for i in range(n):
        free[:, i] = signal.lfilter(numerators[3 + i], den, impulse)[1:]
    return forced, free


def simulate_model(
    gain: float,
    taus: Sequence[float],
    u: np.ndarray,
    ts: float,
    *,
    delay: float = 0.0,
    initial_state: Sequence[float] | Literal["steady"] = "steady",
    hold: Hold = "foh",
) -> np.ndarray:
    """Output of ``gain * exp(-delay s) / prod(1 + tau_i s)`` for the sampled input ``u``.

    ``initial_state`` is in output units (first entry = output at the first sample); "steady"
    means at rest with the input's first value.
    """
    u = _as_signal(u, "u")
    ts = _check_ts(ts)
    taus = tuple(float(t) for t in taus)
    if not taus or any(not (math.isfinite(t) and t > 0) for t in taus):
        raise ValueError(f"simulate_model: taus must be positive and finite, got {taus}")
    if not (math.isfinite(delay) and delay >= 0):
        raise ValueError(f"simulate_model: delay must be finite and >= 0, got {delay}")
    if hold not in HOLDS:
        raise ValueError(f"simulate_model: hold must be one of {HOLDS}, got {hold!r}")
    forced, free = _responses(taus, delay, ts, hold, u)
    if isinstance(initial_state, str):
        if initial_state != "steady":
            raise ValueError(f"simulate_model: unknown initial_state {initial_state!r}")
        x0 = np.full(len(taus), gain * u[0])
    else:
        x0 = np.asarray(initial_state, dtype=float)
        if x0.shape != (len(taus),):
            raise ValueError(
                f"simulate_model: initial_state needs {len(taus)} values, got {x0.shape}"
            )
    return gain * forced + free @ x0


def simulate_fit(
    fit: TfFit,
    u: np.ndarray,
    ts: float | None = None,
    *,
    initial_state: Sequence[float] | Literal["fit", "steady"] = "fit",
) -> np.ndarray:
    """Simulate a fitted model for the input ``u`` (``compare``).

    By default the fitted initial state is used, which reproduces the fit on its own data.
    """
    ts = fit.sample_interval if ts is None else ts
    x0: Sequence[float] | Literal["steady"]
    if isinstance(initial_state, str):
        x0 = fit.initial_state if initial_state == "fit" else "steady"
        if initial_state not in ("fit", "steady"):
            raise ValueError(f"simulate_fit: unknown initial_state {initial_state!r}")
    else:
        x0 = initial_state
    return simulate_model(
        fit.gain,
        fit.taus,
        u,
        ts,
        delay=fit.delay,
        initial_state=x0,
        hold=fit.hold,  # type: ignore[arg-type]
    )


# --------------------------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------------------------


def _as_signal(x: Any, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name}: non-finite value at index {int(bad[0])}")
    return arr


def _check_ts(ts: Any) -> float:
    try:
        value = float(ts)
    except (TypeError, ValueError):
        raise ValueError(f"sample interval must be a number, got {ts!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"sample interval must be finite and > 0, got {value}")
    return value


def _sample_interval(t_or_ts: Any, size: int) -> float:
    if np.ndim(t_or_ts) == 0:
        return _check_ts(t_or_ts)
    t = _as_signal(t_or_ts, "t")
    if t.size != size:
        raise ValueError(f"t: length {t.size} differs from the signals' length {size}")
    dt = np.diff(t)
    if dt.size == 0 or np.any(dt <= 0):
        bad = int(np.flatnonzero(dt <= 0)[0]) + 1 if dt.size else 0
        raise ValueError(f"t: time not strictly increasing at index {bad}")
    interval = float(np.median(dt))
    allowed = _IRREGULAR_TIME_TOLERANCE * interval + 8.0 * float(np.spacing(np.max(np.abs(t))))
    irregular = np.flatnonzero(np.abs(dt - interval) > allowed)
    if irregular.size:
        raise ValueError(
            f"t: irregular time step at index {int(irregular[0]) + 1} "
            f"({dt[irregular[0]]:.10g} vs median {interval:.10g}); resample first"
        )
    return float((t[-1] - t[0]) / (t.size - 1))


@dataclass
class _Problem:
    u: np.ndarray
    y: np.ndarray
    ts: float
    order: int
    delay_estimated: bool
    hold: str
    initial: str
    evaluations: int = 0

    def linear_design(self, taus: Sequence[float], delay: float) -> np.ndarray:
        """Columns multiplying the linear parameters [K, x0...] (or [K] when steady)."""
        self.evaluations += 1
        forced, free = _responses(taus, delay, self.ts, self.hold, self.u)
        if self.initial == "steady":
            # At rest with u[0]: x0 = K u[0] for every state.
            return (forced + free.sum(axis=1) * self.u[0])[:, None]
        return np.column_stack([forced, free])

    def projected(self, nonlinear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Variable projection: residual and linear parameters for given log-taus (, delay)."""
        taus = np.exp(nonlinear[: self.order])
        delay = float(nonlinear[self.order]) if self.delay_estimated else 0.0
        design = self.linear_design(taus, delay)
        coef, *_ = linalg.lstsq(design, self.y, check_finite=False, lapack_driver="gelsy")
        return self.y - design @ coef, coef


def _unpack(problem: _Problem, theta: np.ndarray) -> tuple[float, np.ndarray, float, np.ndarray]:
    """theta = [K, tau_1..tau_n, (delay), (x0_1..x0_n)] in physical units."""
    n = problem.order
    gain = float(theta[0])
    taus = np.asarray(theta[1 : 1 + n])
    pos = 1 + n
    delay = 0.0
    if problem.delay_estimated:
        delay = float(theta[pos])
        pos += 1
    if problem.initial == "steady":
        x0 = np.full(n, gain * problem.u[0])
    else:
        x0 = np.asarray(theta[pos : pos + n])
    return gain, taus, delay, x0


def _model_output(problem: _Problem, theta: np.ndarray) -> np.ndarray:
    gain, taus, delay, x0 = _unpack(problem, theta)
    problem.evaluations += 1
    forced, free = _responses(taus, delay, problem.ts, problem.hold, problem.u)
    return gain * forced + free @ x0


def _initial_candidates(problem: _Problem, duration: float) -> list[np.ndarray]:
    """Coarse multi-start grid over the nonlinear parameters (log-taus, delay)."""
    ts = problem.ts
    low = math.log(max(ts * 0.2, 1e-9))
    high = math.log(max(duration, 10 * ts))
    grid = np.linspace(low, high, 13)
    delays = [0.0]
    if problem.delay_estimated:
        delays = [0.0, *list(np.geomspace(ts, max(duration * 0.1, 2 * ts), 4))]
    candidates: list[np.ndarray] = []
    if problem.order == 1:
        for delay in delays:
            for g in grid:
                candidates.append(np.array([g, delay][: 1 + problem.delay_estimated]))
    else:
        for delay in delays:
            for i, ga in enumerate(grid):
                for gb in grid[:i]:
                    candidates.append(np.array([ga, gb, delay][: 2 + problem.delay_estimated]))
    return candidates


def _search(problem: _Problem, duration: float, n_local: int) -> np.ndarray:
    """Best nonlinear parameters by grid scan then local variable-projection fits."""
    scored: list[tuple[float, np.ndarray]] = []
    for cand in _initial_candidates(problem, duration):
        res, _ = problem.projected(cand)
        scored.append((float(res @ res), cand))
    scored.sort(key=lambda item: item[0])
    n = problem.order
    log_low = math.log(problem.ts * 1e-3)
    log_high = math.log(duration * 1e3)
    lower = [log_low] * n + ([0.0] if problem.delay_estimated else [])
    upper = [log_high] * n + ([duration * 0.5] if problem.delay_estimated else [])
    best: tuple[float, np.ndarray] | None = None
    seen: list[np.ndarray] = []
    for _, start in scored:
        if len(seen) >= n_local:
            break
        # Skip starts equivalent to one already tried (swapped taus, same neighbourhood).
        key = np.concatenate([np.sort(start[:n]), start[n:]])
        if any(np.allclose(key, other, atol=0.3) for other in seen):
            continue
        seen.append(key)
        x0 = np.clip(start, lower, upper)
        # Levenberg-Marquardt (MINPACK) is much cheaper per step than the bounded solver on
        # long records; the box is enforced by clipping inside the residual (flat outside).
        sol = optimize.least_squares(
            lambda p: problem.projected(np.clip(p, lower, upper))[0],
            x0,
            method="lm",
            xtol=1e-10,
            ftol=1e-12,
            max_nfev=200,
        )
        cost = float(sol.fun @ sol.fun)
        if best is None or cost < best[0]:
            best = (cost, np.clip(sol.x, lower, upper))
    assert best is not None
    return best[1]


def _jacobian(problem: _Problem, theta: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of the model output with respect to theta."""
    jac = np.empty((problem.y.size, theta.size))
    for j in range(theta.size):
        step = 1e-5 * scale[j]
        hi = theta.copy()
        lo = theta.copy()
        hi[j] += step
        lo[j] -= step
        if problem.delay_estimated and j == 1 + problem.order and lo[j] < 0:
            lo[j] = theta[j]  # one-sided at the delay bound
        jac[:, j] = (_model_output(problem, hi) - _model_output(problem, lo)) / (hi[j] - lo[j])
    return jac


def _full_parameters(problem: _Problem, nonlinear: np.ndarray) -> np.ndarray:
    """[K, taus, (delay), (x0)] from the nonlinear parameters by solving for the linear ones."""
    _, coef = problem.projected(nonlinear)
    parts: list[np.ndarray] = [coef[:1], np.exp(nonlinear[: problem.order])]
    if problem.delay_estimated:
        parts.append(np.asarray(nonlinear[problem.order :], dtype=float))
    if problem.initial == "estimate":
        parts.append(coef[1:])
    return np.concatenate(parts)


def _parameter_scale(problem: _Problem, theta: np.ndarray) -> np.ndarray:
    """Typical magnitudes of the parameters (finite-difference steps, solver scaling)."""
    n = problem.order
    scale = np.abs(theta).astype(float)
    scale[0] = max(scale[0], 1e-3)
    scale[1 : 1 + n] = np.maximum(scale[1 : 1 + n], problem.ts * 1e-3)
    pos = 1 + n
    if problem.delay_estimated:
        scale[pos] = max(scale[pos], problem.ts)
        pos += 1
    if problem.initial == "estimate":
        level = max(1.0, float(np.std(problem.y)))
        scale[pos:] = np.maximum(scale[pos:], level)
    return scale


def _robust_noise_std(x: np.ndarray) -> float:
    """White-noise level from second differences (MAD; var(d2 e) = 6 sigma^2), robust to steps
    and blind to smooth signal."""
    d2 = np.diff(x, 2)
    if d2.size < 3:
        return 0.0
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.482602218505602 * mad / math.sqrt(6.0)


def _input_response(problem: _Problem, theta: np.ndarray) -> np.ndarray:
    """Impulse response h of the fitted map from input samples to output samples
    (yhat = h * u plus the free response), length N."""
    gain, taus, delay, _ = _unpack(problem, theta)
    size = problem.y.size
    lead = math.floor(delay / problem.ts) + 3  # past the start-up padding of the input
    impulse = np.zeros(size + lead)
    impulse[lead] = 1.0
    forced, _ = _responses(taus, delay, problem.ts, problem.hold, impulse)
    return gain * forced[lead:]


def _covariance(
    jac: np.ndarray,
    residual: np.ndarray,
    input_response: np.ndarray | None = None,
    input_noise_std: float = 0.0,
) -> np.ndarray:
    """Parameter covariance (column-equilibrated for conditioning).

    Output noise: s^2 (J^T J)^-1 with s^2 = SSE / (N - p). Input noise w (white, sigma_u) moves
    the model output by H w (H = convolution with the input response h), hence the estimate by
    -(J^T J)^-1 J^T H w: add sigma_u^2 (J^T J)^-1 (H^T J)^T (H^T J) (J^T J)^-1, and remove the
    share sigma_u^2 |h|^2 of the residual variance that it explains.
    """
    size, k = jac.shape
    variance = float(residual @ residual) / max(size - k, 1)
    jtj = jac.T @ jac
    norms = np.sqrt(np.diag(jtj))
    norms[norms == 0] = 1.0
    inv = linalg.pinvh(jtj / np.outer(norms, norms)) / np.outer(norms, norms)
    if input_response is None or input_noise_std <= 0:
        return variance * inv
    h = input_response
    # H^T J: correlate every Jacobian column with h (time-reversed convolution, by FFT).
    ht_j = np.column_stack([signal.fftconvolve(jac[::-1, j], h)[:size][::-1] for j in range(k)])
    output_variance = max(variance - input_noise_std**2 * float(h @ h), 0.0)
    middle = ht_j.T @ ht_j
    return output_variance * inv + input_noise_std**2 * (inv @ middle @ inv)


def fit_transfer_function(
    t_or_ts: float | np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    order: int = 1,
    delay: bool = False,
    *,
    hold: Hold = "foh",
    initial: Initial = "estimate",
    n_starts: int = 4,
    input_noise_std: float | Literal["auto"] | None = "auto",
) -> TfFit:
    """Fit ``K exp(-theta s) / prod(1 + tau_i s)`` from input ``u`` to output ``y``.

    Parameters
    ----------
    t_or_ts:
        Sample interval in seconds, or the (regular) time vector.
    u, y:
        Input (reference measurement) and output (sensor) samples, same length.
    order:
        1 or 2 (number of real poles).
    delay:
        Also estimate a dead time ``theta >= 0``.
    hold:
        Inter-sample behaviour of the input: "foh" (linear, default) or "zoh" (constant).
    initial:
        "estimate" (initial state fitted, default) or "steady" (at rest with ``u[0]``).
    n_starts:
        Number of local searches started from the best points of the coarse grid.
    input_noise_std:
        White noise on the measured input, propagated into the parameter uncertainties
        (errors in variables: input noise filtered by the model is slow, and the fit absorbs
        its low-frequency part into the parameters, so the residuals cannot reveal it).
        "auto" (default) estimates it robustly from the input's second differences, which is
        right for a smooth measured signal and conservative for an input that is rough at the
        sample scale; None or 0 treats the input as exact (what tfest does).

    Raises
    ------
    ValueError
        Bad arguments or signals (with what and where).
    IdentificationError
        The input does not excite the model (constant input or output).
    """
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    if hold not in HOLDS:
        raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
    if initial not in INITIAL_CONDITIONS:
        raise ValueError(f"initial must be one of {INITIAL_CONDITIONS}, got {initial!r}")
    if not (isinstance(n_starts, int) and n_starts >= 1):
        raise ValueError(f"n_starts must be a positive integer, got {n_starts!r}")
    if not (
        input_noise_std is None
        or input_noise_std == "auto"
        or (
            isinstance(input_noise_std, (int, float))
            and math.isfinite(input_noise_std)
            and input_noise_std >= 0
        )
    ):
        raise ValueError(
            f"input_noise_std must be 'auto', None or a finite number >= 0, got {input_noise_std!r}"
        )
    u = _as_signal(u, "u")
    y = _as_signal(y, "y")
    if u.size != y.size:
        raise ValueError(f"u and y differ in length ({u.size} vs {y.size})")
    ts = _sample_interval(t_or_ts, u.size)
    n_params = 1 + order + int(delay) + (order if initial == "estimate" else 0)
    min_samples = max(10, 3 * n_params)
    if u.size < min_samples:
        raise ValueError(f"too few samples ({u.size}; need at least {min_samples})")
    u_spread = float(np.ptp(u))
    if u_spread <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
        raise IdentificationError("the input is constant: it does not excite the model")
    if float(np.ptp(y)) == 0.0:
        raise IdentificationError("the output is constant: nothing to fit")

    problem = _Problem(u, y, ts, order, delay, hold, initial)
    duration = ts * (u.size - 1)
    nonlinear = _search(problem, duration, n_starts)
    theta = _full_parameters(problem, nonlinear)

    # Polish all parameters together (physical units, scaled) and get the Jacobian there.
    scale = _parameter_scale(problem, theta)
    # Internally the time constants are logarithms (positive, scale-free) and the dead time is
    # clipped at zero; Levenberg-Marquardt as in the search.
    tau_slice = slice(1, 1 + order)

    def to_physical(internal: np.ndarray) -> np.ndarray:
        physical = internal.copy()
        physical[tau_slice] = np.exp(internal[tau_slice])
        if delay:
            physical[1 + order] = max(internal[1 + order], 0.0)
        return physical

    internal = theta.copy()
    internal[tau_slice] = np.log(theta[tau_slice])
    internal_scale = scale.copy()
    internal_scale[tau_slice] = 1.0
    sol = optimize.least_squares(
        lambda p: y - _model_output(problem, to_physical(p)),
        internal,
        x_scale=internal_scale,
        method="lm",
        xtol=1e-12,
        ftol=1e-14,
        gtol=1e-12,
        max_nfev=100 * theta.size,
    )
    theta = to_physical(sol.x)
    if order == 2 and theta[1] < theta[2]:
        # Report tau_a >= tau_b: re-express the same model with the lags swapped (the initial
        # state refers to the cascade, so it is re-solved for the new ordering).
        swapped = np.log(theta[[2, 1]])
        if delay:
            swapped = np.append(swapped, theta[3])
        theta = _full_parameters(problem, swapped)
    residual = y - _model_output(problem, theta)
    jac = _jacobian(problem, theta, _parameter_scale(problem, theta))
    sigma_u = (
        _robust_noise_std(u) if input_noise_std == "auto" else float(input_noise_std or 0.0)  # type: ignore[arg-type]
    )
    response = _input_response(problem, theta) if sigma_u > 0 else None
    cov = _covariance(jac, residual, response, sigma_u)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))

    names = ["gain", *(["tau"] if order == 1 else ["tau_a", "tau_b"])]
    if delay:
        names.append("delay")
    if initial == "estimate":
        names += [f"x0_{i + 1}" for i in range(order)]
    gain, taus, delay_value, x0 = _unpack(problem, theta)
    pos = 1 + order + int(delay)
    x0_std = (
        tuple(float(v) for v in std[pos : pos + order]) if initial == "estimate" else (0.0,) * order
    )
    size = y.size
    sse = float(residual @ residual)

    rmse = math.sqrt(sse / size)
    spread = float(np.linalg.norm(y - np.mean(y)))
    fit_percent = 100.0 * (1.0 - math.sqrt(sse) / spread)
    k = theta.size
    # Gaussian log-likelihood with the ML variance; same convention as MATLAB's aic/bic.
    log_like_term = size * math.log(max(sse / size, np.finfo(float).tiny))
    constant = size * (math.log(2 * math.pi) + 1.0)
    aic = log_like_term + 2 * k + constant
    aicc = aic + (2 * k * (k + 1) / (size - k - 1) if size - k - 1 > 0 else math.inf)
    bic = log_like_term + k * math.log(size) + constant
    centred = residual - residual.mean()
    denom = float(centred @ centred)
    acf1 = float(centred[1:] @ centred[:-1] / denom) if denom > 0 else 0.0

    return TfFit(
        order=order,
        gain=float(gain),
        gain_std=float(std[0]),
        taus=tuple(float(v) for v in taus),
        taus_std=tuple(float(v) for v in std[1 : 1 + order]),
        delay=float(delay_value),
        delay_std=float(std[1 + order]) if delay else 0.0,
        delay_estimated=bool(delay),
        initial_state=tuple(float(v) for v in x0),
        initial_state_std=x0_std,
        sample_interval=ts,
        n_samples=size,
        n_parameters=k,
        rmse=rmse,
        fit_percent=fit_percent,
        aic=aic,
        aicc=aicc,
        bic=bic,
        residual_autocorrelation=acf1,
        input_noise_std=sigma_u,
        hold=hold,
        initial=initial,
        parameter_names=tuple(names),
        covariance=tuple(tuple(float(v) for v in row) for row in cov),
        n_function_evaluations=problem.evaluations,
    )
