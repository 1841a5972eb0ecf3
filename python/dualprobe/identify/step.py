"""Plunge tests: a sensor's step response fitted without a reference measurement.

A plunge (the sensor moved into a bath or a gas stream at another temperature) is an ideal step
of the sensor's input at an unknown instant. :func:`fit_step` finds it and fits

    y(t) = L0                                 for t < t0
    y(t) = L0 + (L1 - L0) g(t - t0)           after,

with ``g(s) = 1 - exp(-s/tau)`` (order 1) or
``g(s) = 1 - (tau_a exp(-s/tau_a) - tau_b exp(-s/tau_b)) / (tau_a - tau_b)`` (order 2), by least
squares on the analytic response: the onset ``t0`` is continuous (not tied to the sample grid),
the levels are linear parameters solved at every trial (variable projection), and the order is
chosen by BIC (order 2 only with strong evidence: BIC lower by 10) unless given.

What is identifiable: without a trigger signal the plunge instant and a dead time cannot be told
apart, so ``onset`` is the instant the response starts (plunge instant + dead time).

Logger effects: a reading held for k rows (a logger refreshing every k samples) is detected
from where the readings change (all changes on one phase of k rows) and only the refresh rows
are fitted, at their own instants, so the hold biases nothing and the residuals stay white.
Quantisation (e.g. 0.25 K) is reported and enters as noise; the noise level comes from
:func:`dualprobe.models.noise.estimate_noise_std` with its quantisation floor.

``bath``: the known temperature the sensor is plunged into; the offset is then the fitted final
level minus it (the sensor's static error), with its standard deviation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg, optimize

from dualprobe.identify.result import IdentificationError
from dualprobe.models.jacobian import central_jacobian
from dualprobe.models.noise import ORDER_IDENTIFY, estimate_noise_std

__all__ = ["MIN_STEP_NOISE_RATIO", "StepFit", "detect_hold", "fit_step", "step_response"]

# The plunge must move the output by this many noise standard deviations.
MIN_STEP_NOISE_RATIO = 10.0
# BIC advantage order 2 needs over order 1 ("very strong" evidence on Kass and Raftery's scale).
ORDER2_BIC_MARGIN = 10.0
# Share of the reading changes that must fall on one phase of k rows to call it a hold of k.
HOLD_SHARE = 0.98


def step_response(s: np.ndarray, taus: tuple[float, ...] | list[float]) -> np.ndarray:
    """Unit step response ``g(s)`` of ``1 / prod(1 + tau_i s)`` (zero for s <= 0)."""
    s = np.maximum(np.asarray(s, dtype=float), 0.0)
    if len(taus) == 1:
        return -np.expm1(-s / taus[0])
    tau_a, tau_b = float(taus[0]), float(taus[1])
    if abs(tau_a - tau_b) <= 1e-6 * max(tau_a, tau_b):
        tau = 0.5 * (tau_a + tau_b)
        return 1.0 - (1.0 + s / tau) * np.exp(-s / tau)
    return 1.0 - (tau_a * np.exp(-s / tau_a) - tau_b * np.exp(-s / tau_b)) / (tau_a - tau_b)


def detect_hold(y: np.ndarray, max_hold: int = 32) -> tuple[int, int]:
    """(k, phase): the readings change only on rows ``phase + j k``; (1, 0) when not held."""
    changes = np.flatnonzero(np.diff(y) != 0.0) + 1
    if changes.size < 20:
        return 1, 0
    for k in range(max_hold, 1, -1):
        counts = np.bincount(changes % k, minlength=k)
        if counts.max() >= HOLD_SHARE * changes.size:
            return k, int(np.argmax(counts))
    return 1, 0


def _quantisation(y: np.ndarray) -> float:
    steps = np.abs(np.diff(y))
    steps = steps[steps > 0]
    if steps.size == 0:
        return 0.0
    q = float(np.min(steps))
    lattice = (y - y[0]) / q
    return q if float(np.max(np.abs(lattice - np.rint(lattice)))) < 1e-3 else 0.0


@dataclass(frozen=True)
class StepFit:
    """Result of :func:`fit_step` (1-sigma uncertainties from the Jacobian, white residuals)."""

    order: int
    taus: tuple[float, ...]
    taus_std: tuple[float, ...]
    onset: float
    onset_std: float
    initial_level: float
    initial_level_std: float
    final_level: float
    final_level_std: float
    hold: int
    hold_phase: int
    quantisation: float
    noise_std: float
    n_samples: int
    n_fitted: int
    rmse: float
    fit_percent: float
    aicc: float
    bic: float
    residual_autocorrelation: float
    bic_by_order: dict[int, float] = field(default_factory=dict)
    bath: float | None = None
    offset: float | None = None
    offset_std: float | None = None

    def response(self, t: np.ndarray) -> np.ndarray:
        """The fitted step response at the instants ``t`` (s)."""
        return self.initial_level + (self.final_level - self.initial_level) * step_response(
            np.asarray(t, dtype=float) - self.onset, self.taus)

    @property
    def model(self) -> str:
        poles = "".join(f"(1+{tau:.4g}s)" for tau in sorted(self.taus))
        return f"step {self.initial_level:.4g} -> {self.final_level:.4g} at {self.onset:.6g} s " + (
            f"through 1/{poles}" if self.order == 1 else f"through 1/({poles})"
        )

    def summary(self) -> str:
        lines = [f"plunge  {self.model}"]
        names = ["tau"] if self.order == 1 else ["tau_a", "tau_b"]
        for name, value, std in zip(names, self.taus, self.taus_std, strict=True):
            lines.append(f"  {name:<13} = {value:.6g} +/- {std:.2g} s")
        lines.append(
            f"  onset         = {self.onset:.6g} +/- {self.onset_std:.2g} s "
            "(plunge instant + dead time)"
        )
        lines.append(
            f"  levels        = {self.initial_level:.6g} +/- {self.initial_level_std:.2g} -> "
            f"{self.final_level:.6g} +/- {self.final_level_std:.2g}"
        )
        if self.offset is not None and self.offset_std is not None:
            lines.append(
                f"  offset        = {self.offset:.4g} +/- {self.offset_std:.2g} "
                f"(final level - bath {self.bath:g})"
            )
        orders = ", ".join(f"order {k}: {v:.6g}" for k, v in sorted(self.bic_by_order.items()))
        lines.append(
            f"fit {self.fit_percent:.2f} % (NRMSE)   RMSE {self.rmse:.4g}   BIC {orders}"
        )
        logger = f"reading held {self.hold} rows (refresh rows fitted)" if self.hold > 1 else ""
        if self.quantisation > 0:
            logger += ("; " if logger else "") + f"quantised to {self.quantisation:.4g}"
        lines.append(
            f"{self.n_fitted} of {self.n_samples} samples fitted, noise std {self.noise_std:.3g}"
            + (f", {logger}" if logger else "")
            + f", residual lag-1 autocorrelation {self.residual_autocorrelation:.2f}"
        )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": "step",
            "model": self.model,
            "order": self.order,
            "taus": list(self.taus),
            "taus_std": list(self.taus_std),
            "onset": self.onset,
            "onset_std": self.onset_std,
            "initial_level": self.initial_level,
            "initial_level_std": self.initial_level_std,
            "final_level": self.final_level,
            "final_level_std": self.final_level_std,
            "hold": self.hold,
            "hold_phase": self.hold_phase,
            "quantisation": self.quantisation,
            "noise_std": self.noise_std,
            "n_samples": self.n_samples,
            "n_fitted": self.n_fitted,
            "rmse": self.rmse,
            "fit_percent": self.fit_percent,
            "aicc": self.aicc,
            "bic": self.bic,
            "bic_by_order": {str(k): v for k, v in self.bic_by_order.items()},
            "residual_autocorrelation": self.residual_autocorrelation,
            "bath": self.bath,
            "offset": self.offset,
            "offset_std": self.offset_std,
        }


@dataclass
class _Plunge:
    t: np.ndarray
    y: np.ndarray

    def design(self, nonlinear: np.ndarray) -> np.ndarray:
        onset, taus = float(nonlinear[0]), tuple(np.exp(nonlinear[1:]))
        return np.column_stack([np.ones_like(self.t), step_response(self.t - onset, taus)])

    def projected(self, nonlinear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        design = self.design(nonlinear)
        coef, *_ = linalg.lstsq(design, self.y, check_finite=False, lapack_driver="gelsy")
        return self.y - design @ coef, coef

    def output(self, theta: np.ndarray) -> np.ndarray:
        """theta = [L0, L1, onset, taus...]."""
        g = step_response(self.t - theta[2], tuple(theta[3:]))
        return theta[0] + (theta[1] - theta[0]) * g


def _smooth(y: np.ndarray, width: int) -> np.ndarray:
    if width <= 1:
        return y
    kernel = np.ones(width) / width
    padded = np.concatenate([np.full(width, y[0]), y, np.full(width, y[-1])])
    return np.convolve(padded, kernel, mode="same")[width:-width]


def _guesses(t: np.ndarray, y: np.ndarray, sigma: float, q: float) -> tuple[float, float, float]:
    """(onset, tau, step) first guesses from the largest change of the smoothed signal."""
    smooth = _smooth(y, max(3, min(25, y.size // 50)))
    slope = np.diff(smooth) / np.diff(t)
    peak = int(np.argmax(np.abs(slope)))
    tail = max(5, y.size // 10)
    before = float(np.median(y[: max(peak - 2, 1)]))
    after = float(np.median(y[-tail:]))
    step = after - before
    threshold = max(MIN_STEP_NOISE_RATIO * sigma, 4.0 * q)
    if not abs(step) > threshold:
        raise IdentificationError(
            f"no plunge: the output moves by {abs(step):.3g} between its first and last "
            f"levels, under {MIN_STEP_NOISE_RATIO:g} noise std ({sigma:.3g}); record a step "
            "of the sensor's temperature"
        )
    rel = (smooth - before) / step
    left = np.flatnonzero(rel[: peak + 1] < 0.05)
    start = int(left[-1]) if left.size else 0
    above = np.flatnonzero(rel[start:] >= 1.0 - math.exp(-1.0))
    tau = float(t[start + int(above[0])] - t[start]) if above.size else float(t[-1] - t[start])
    ts = float(np.median(np.diff(t)))
    return float(t[start]), max(tau, ts), step


def _fit_order(problem: _Plunge, order: int, onset: float, tau: float, ts: float) -> np.ndarray:
    """Best nonlinear parameters [onset, log taus] from a few starts."""
    if order == 1:
        starts = [[onset + d * ts, math.log(tau * f)] for d in (-1, 0, 1) for f in (0.7, 1.0)]
    else:
        starts = [
            [onset - b * tau, math.log(a * tau), math.log(b * tau)]
            for a, b in ((0.9, 0.1), (0.7, 0.3), (0.55, 0.45))
        ]
    best: tuple[float, np.ndarray] | None = None
    for start in starts:
        sol = optimize.least_squares(
            lambda p: problem.projected(p)[0],
            np.asarray(start, dtype=float),
            x_scale=np.array([max(ts, 0.05 * tau)] + [1.0] * order),
            method="lm",
            xtol=1e-12,
            ftol=1e-12,
            max_nfev=400,
        )
        cost = float(sol.fun @ sol.fun)
        if best is None or cost < best[0]:
            best = (cost, sol.x)
    assert best is not None
    return best[1]


def _statistics(
    problem: _Plunge, nonlinear: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(theta, std, residual, bic) at the optimum; theta = [L0, L1, onset, taus]."""
    _, coef = problem.projected(nonlinear)
    taus = np.exp(nonlinear[1:])
    order = taus.size
    if order == 2 and taus[0] < taus[1]:
        taus = taus[::-1]
    theta = np.concatenate([[coef[0], coef[0] + coef[1], nonlinear[0]], taus])
    residual = problem.y - problem.output(theta)
    scale = np.maximum(np.abs(theta), 1e-3)
    # a time constant's step is relative: an absolute one crossed zero when a degenerate
    # order-2 fit drove tau_b towards 0 (a drifting bath), and exp(-s / tau) overflowed
    scale[3:] = np.maximum(taus, np.finfo(float).tiny)
    step = 1e-6 * scale
    jac = central_jacobian(problem.output, theta, theta + step, theta - step)
    size, k = jac.shape
    variance = float(residual @ residual) / max(size - k, 1)
    cov = variance * linalg.pinvh(jac.T @ jac)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    sse = max(float(residual @ residual), np.finfo(float).tiny)
    bic = size * math.log(sse / size) + k * math.log(size) + size * (math.log(2 * math.pi) + 1)
    return theta, std, residual, bic


def fit_step(
    t: np.ndarray,
    y: np.ndarray,
    *,
    order: int | None = None,
    bath: float | None = None,
) -> StepFit:
    """Fit a plunge test (see the module docstring).

    ``t`` in seconds (increasing; gaps allowed), ``y`` the sensor's readings; ``order`` 1 or 2
    (None: chosen by BIC); ``bath`` the known final temperature for the offset.

    Raises ValueError for bad arguments, IdentificationError when the output has no step.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.ndim != 1 or t.shape != y.shape:
        raise ValueError(f"t and y must be 1-D of equal length, got {t.shape} and {y.shape}")
    if order not in (None, 1, 2):
        raise ValueError(f"order must be 1, 2 or None, got {order!r}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise ValueError("t and y must be finite")
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("t must be strictly increasing")
    hold, phase = detect_hold(y)
    rows = np.arange(phase, y.size, hold)
    problem = _Plunge(t[rows], y[rows])
    if problem.y.size < 20:
        raise ValueError(f"too few samples for a plunge fit ({problem.y.size}; need 20)")
    q = _quantisation(problem.y)
    sigma = estimate_noise_std(problem.y, ORDER_IDENTIFY)
    onset, tau, _ = _guesses(problem.t, problem.y, sigma, q)
    ts = float(np.median(np.diff(problem.t)))
    fits: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, float]] = {}
    for candidate in (1, 2) if order is None else (order,):
        nonlinear = _fit_order(problem, candidate, onset, tau, ts)
        fits[candidate] = _statistics(problem, nonlinear)
    chosen = order or (
        2 if 2 in fits and fits[2][3] < fits[1][3] - ORDER2_BIC_MARGIN else 1
    )
    theta, std, residual, bic = fits[chosen]
    size, k = problem.y.size, theta.size
    sse = float(residual @ residual)
    spread = float(np.linalg.norm(problem.y - problem.y.mean()))
    aic = size * math.log(max(sse / size, np.finfo(float).tiny)) + 2 * k
    aic += size * (math.log(2 * math.pi) + 1)
    aicc = aic + (2 * k * (k + 1) / (size - k - 1) if size - k - 1 > 0 else math.inf)
    centred = residual - residual.mean()
    denom = float(centred @ centred)
    offset = offset_std = None
    if bath is not None:
        offset, offset_std = float(theta[1] - bath), float(std[1])
    return StepFit(
        order=chosen,
        taus=tuple(float(v) for v in theta[3:]),
        taus_std=tuple(float(v) for v in std[3:]),
        onset=float(theta[2]),
        onset_std=float(std[2]),
        initial_level=float(theta[0]),
        initial_level_std=float(std[0]),
        final_level=float(theta[1]),
        final_level_std=float(std[1]),
        hold=hold,
        hold_phase=phase,
        quantisation=q,
        noise_std=sigma,
        n_samples=int(y.size),
        n_fitted=int(size),
        rmse=math.sqrt(sse / size),
        fit_percent=100.0 * (1.0 - math.sqrt(sse) / spread) if spread > 0 else 0.0,
        aicc=aicc,
        bic=bic,
        residual_autocorrelation=float(centred[1:] @ centred[:-1] / denom) if denom > 0 else 0.0,
        bic_by_order={key: value[3] for key, value in fits.items()},
        bath=bath,
        offset=offset,
        offset_std=offset_std,
    )
