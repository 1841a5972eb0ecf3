"""Output-error fit of a transfer function from a reference measurement to a sensor
(:func:`fit_transfer_function`; the method in the :mod:`dualprobe.identify` docstring)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from scipy import linalg, optimize, signal

from dualprobe.identify.model import as_signal, check_ts, responses
from dualprobe.identify.result import (
    HOLDS,
    INITIAL_CONDITIONS,
    Hold,
    IdentificationError,
    Initial,
    TfFit,
)
from dualprobe.io.timebase import IRREGULAR_TIME_TOLERANCE
from dualprobe.models.jacobian import central_jacobian
from dualprobe.models.noise import ORDER_IDENTIFY, estimate_noise_std

__all__ = ["fit_transfer_function"]


def _sample_interval(t_or_ts: Any, size: int) -> float:
    if np.ndim(t_or_ts) == 0:
        return check_ts(t_or_ts)
    t = as_signal(t_or_ts, "t")
    if t.size != size:
        raise ValueError(f"t: length {t.size} differs from the signals' length {size}")
    dt = np.diff(t)
    if dt.size == 0 or np.any(dt <= 0):
        bad = int(np.flatnonzero(dt <= 0)[0]) + 1 if dt.size else 0
        raise ValueError(f"t: time not strictly increasing at index {bad}")
    interval = float(np.median(dt))
    allowed = IRREGULAR_TIME_TOLERANCE * interval + 8.0 * float(np.spacing(np.max(np.abs(t))))
    irregular = np.flatnonzero(np.abs(dt - interval) > allowed)
    if irregular.size:
        raise ValueError(
            f"t: irregular time step at index {int(irregular[0]) + 1} "
            f"({dt[irregular[0]]:.10g} vs median {interval:.10g}); resample first"
        )
    return float((t[-1] - t[0]) / (t.size - 1))


def _check_excitation(u: np.ndarray) -> None:
    """Refuse an input whose range is within what its noise alone spans (the expected range of
    N Gaussian samples is about 2 sqrt(2 ln N) noise std; 4 more is the margin)."""
    sigma = estimate_noise_std(u, ORDER_IDENTIFY)
    spread = float(np.ptp(u))
    needed = (2.0 * math.sqrt(2.0 * math.log(u.size)) + 4.0) * sigma
    if sigma > 0 and spread < needed:
        raise IdentificationError(
            f"no excitation: the input spans {spread:.3g}, within what its noise "
            f"({sigma:.3g} std) spans alone (need > {needed:.3g}); record a change of the input"
        )


@dataclass
class _Problem:
    u: np.ndarray
    y: np.ndarray
    ts: float
    order: int
    delay_estimated: bool
    hold: str
    initial: str
    offset: bool = False
    evaluations: int = 0

    def linear_design(self, taus: Sequence[float], delay: float) -> np.ndarray:
        """Columns multiplying the linear parameters [K, x0...] (or [K] when steady)."""
        self.evaluations += 1
        forced, free = responses(taus, delay, self.ts, self.hold, self.u)
        if self.initial == "steady":
            # At rest with u[0]: x0 = K u[0] for every state.
            columns = [(forced + free.sum(axis=1) * self.u[0])[:, None]]
        else:
            columns = [forced[:, None], free]
        if self.offset:
            columns.append(np.ones((forced.size, 1)))
        return np.hstack(columns)

    def projected(self, nonlinear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Variable projection: residual and linear parameters for given log-taus (, delay)."""
        taus = np.exp(nonlinear[: self.order])
        delay = float(nonlinear[self.order]) if self.delay_estimated else 0.0
        design = self.linear_design(taus, delay)
        coef, *_ = linalg.lstsq(design, self.y, check_finite=False, lapack_driver="gelsy")
        return self.y - design @ coef, coef


def _unpack(problem: _Problem, theta: np.ndarray) -> tuple[float, np.ndarray, float, np.ndarray]:
    """theta = [K, tau_1..tau_n, (delay), (x0_1..x0_n), (offset)] in physical units."""
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


def _offset(problem: _Problem, theta: np.ndarray) -> float:
    """The additive output offset (the last parameter when estimated)."""
    return float(theta[-1]) if problem.offset else 0.0


def _model_output(problem: _Problem, theta: np.ndarray) -> np.ndarray:
    gain, taus, delay, x0 = _unpack(problem, theta)
    problem.evaluations += 1
    forced, free = responses(taus, delay, problem.ts, problem.hold, problem.u)
    return gain * forced + free @ x0 + _offset(problem, theta)


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
    step = 1e-5 * scale
    hi, lo = theta + step, theta - step
    taus = slice(1, 1 + problem.order)
    # a time constant below the step (an output that follows its input within a row) would
    # be evaluated negative: a relative step instead
    crossing = lo[taus] <= 0.0
    hi[taus] = np.where(crossing, theta[taus] * (1.0 + 1e-5), hi[taus])
    lo[taus] = np.where(crossing, theta[taus] / (1.0 + 1e-5), lo[taus])
    at = 1 + problem.order
    if problem.delay_estimated and lo[at] < 0:
        lo[at] = theta[at]  # one-sided at the delay bound
    return central_jacobian(lambda p: _model_output(problem, p), theta, hi, lo)


def _full_parameters(problem: _Problem, nonlinear: np.ndarray) -> np.ndarray:
    """[K, taus, (delay), (x0)] from the nonlinear parameters by solving for the linear ones."""
    _, coef = problem.projected(nonlinear)
    parts: list[np.ndarray] = [coef[:1], np.exp(nonlinear[: problem.order])]
    if problem.delay_estimated:
        parts.append(np.asarray(nonlinear[problem.order :], dtype=float))
    if problem.initial == "estimate":
        parts.append(coef[1 : 1 + problem.order])
    if problem.offset:
        parts.append(coef[-1:])
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
    level = max(1.0, float(np.std(problem.y)))
    if problem.initial == "estimate":
        scale[pos : pos + n] = np.maximum(scale[pos : pos + n], level)
    if problem.offset:
        scale[-1] = max(scale[-1], level)
    return scale


def _input_response(problem: _Problem, theta: np.ndarray) -> np.ndarray:
    """Impulse response h of the fitted map from input samples to output samples
    (yhat = h * u plus the free response), length N."""
    gain, taus, delay, _ = _unpack(problem, theta)
    size = problem.y.size
    lead = math.floor(delay / problem.ts) + 3  # past the start-up padding of the input
    impulse = np.zeros(size + lead)
    impulse[lead] = 1.0
    forced, _ = responses(taus, delay, problem.ts, problem.hold, impulse)
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
    offset: bool = False,
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
        "auto" (default) estimates it robustly from the input's second differences
        (:func:`dualprobe.models.noise.estimate_noise_std`), which is
        right for a smooth measured signal and conservative for an input that is rough at the
        sample scale; None or 0 treats the input as exact (what tfest does).
    offset:
        Also estimate an additive output offset ``c``: ``y = K G(s) u + c`` (a sensor reading
        off by a constant, or input and output on different zeros).

    Raises
    ------
    ValueError
        Bad arguments or signals (with what and where).
    IdentificationError
        The input does not excite the model (constant input or output, or an input whose range
        is within what its noise alone spans: ``2 sqrt(2 ln N) + 4`` noise std).
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
    u = as_signal(u, "u")
    y = as_signal(y, "y")
    if u.size != y.size:
        raise ValueError(f"u and y differ in length ({u.size} vs {y.size})")
    ts = _sample_interval(t_or_ts, u.size)
    n_params = 1 + order + int(delay) + (order if initial == "estimate" else 0) + int(offset)
    min_samples = max(10, 3 * n_params)
    if u.size < min_samples:
        raise ValueError(f"too few samples ({u.size}; need at least {min_samples})")
    u_spread = float(np.ptp(u))
    if u_spread <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
        raise IdentificationError("the input is constant: it does not excite the model")
    if float(np.ptp(y)) == 0.0:
        raise IdentificationError("the output is constant: nothing to fit")
    _check_excitation(u)

    problem = _Problem(u, y, ts, order, delay, hold, initial, offset)
    duration = ts * (u.size - 1)
    nonlinear = _search(problem, duration, n_starts)
    theta = _full_parameters(problem, nonlinear)

    # Polish all parameters together (physical units, scaled) and get the Jacobian there.
    scale = _parameter_scale(problem, theta)
    # Internally the time constants are logarithms (positive, scale-free) and the dead time is
    # clipped at zero; Levenberg-Marquardt as in the search.
    tau_slice = slice(1, 1 + order)

    # a time constant a million times below the sample interval is zero to the sampled model
    # (e^(-Ts/tau) underflows long before); below that the polish would overflow
    log_floor, log_ceiling = math.log(ts * 1e-6), math.log(duration * 1e6)

    def to_physical(internal: np.ndarray) -> np.ndarray:
        physical = internal.copy()
        physical[tau_slice] = np.exp(np.clip(internal[tau_slice], log_floor, log_ceiling))
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
    if input_noise_std == "auto":
        sigma_u = estimate_noise_std(u, ORDER_IDENTIFY)
    else:
        sigma_u = float(input_noise_std or 0.0)  # type: ignore[arg-type]
    response = _input_response(problem, theta) if sigma_u > 0 else None
    cov = _covariance(jac, residual, response, sigma_u)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))

    names = ["gain", *(["tau"] if order == 1 else ["tau_a", "tau_b"])]
    if delay:
        names.append("delay")
    if initial == "estimate":
        names += [f"x0_{i + 1}" for i in range(order)]
    if offset:
        names.append("offset")
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
        offset=_offset(problem, theta),
        offset_std=float(std[-1]) if offset else 0.0,
        offset_estimated=offset,
    )
