"""The MAP gas trajectory for one gas model: banded normal equations of the whole trajectory, the
exact Gaussian marginal likelihood in the gas intensity q, and the alternation of Student-t
weights and q (:class:`GasFit`) that :func:`dualprobe.reconstruction.smoother.fit_smoother`
runs for each gas model."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.linalg.lapack
import scipy.optimize

from dualprobe import _core
from dualprobe.reconstruction.statespace import PairModel, process_floor

__all__ = [
    "JUMP_DOF",
    "GasFit",
    "Trajectory",
    "fit_gas_models",
    "gaussian_log_q",
    "initial_modes",
]

JUMP_DOF = 1.0  # Student-t increments: a jump costs ~log(size), not size^2 (not data-tuned)
_MAX_ROUNDS = 25  # alternations weights <-> intensity; typically settles in 3-15
_NEWTON_H = 0.2  # log q step of the parabola (the nll is smooth in log q on this scale)
_NEWTON_MAX = 3.0  # largest log q move per round
_MAX_MODE_PASSES = 6  # hysteresis: re-evaluations of the switching modes
_LOGQ_TOL = 0.1  # 10 % in q: the reconstruction changes by a fraction of that
_START_TOL = 0.5  # log q tolerance of the Gaussian start
_NEAR_STEP = 1.0  # log q step from a nearby model's q (stages moved by their std: 0.007)
_NLL_TOL = 1.0  # settled: the best nll gained less than this over two rounds
_UNUSABLE = 1e100  # nll reported to the optimiser where the normal equations are singular
_WANDER_MIN = 1e-3  # smallest q: the gas wanders by 1e-3 sigma over the whole record
_STEP_MAX = 1e3  # largest q: one step of the gas moves it by 1e3 times the signals' span


class Trajectory:
    """Normal equations of the whole state trajectory for one model and data set.

    Unknowns x_0..x_(N-1) (interleaved, n per sample). Objective (negative log joint density):
    ``1/2 sum r_k^T R^-1 r_k + 1/2 sum lambda_k w_k^T Qb_(m_k)^-1 w_k`` with
    ``r_k = y_k - H x_k``, ``w_k = x_(k+1) - Phi_(m_k) x_k``, ``Qb_m = q Qunit_m + Qfloor``;
    the Hessian is block-tridiagonal with bandwidth 2n - 1.
    """

    def __init__(self, model: PairModel, y: np.ndarray, sigma: np.ndarray,
                 scale: np.ndarray | None = None) -> None:
        """``scale`` (N, 2): each row's noise variance over ``sigma**2`` (a jittered clock:
        :func:`dualprobe.models.jitter.row_noise_scale`); None: every row alike."""
        self.model = model
        self.y = y
        self.n = model.n
        self.samples = y.shape[0]
        self.sigma = sigma
        # each row's noise variance: (2,) when every row is alike, else (N, 2)
        self.variance = sigma**2 if scale is None else sigma**2 * scale
        self.outputs = np.argmax(model.h, axis=1)  # the state each sensor measures
        if scale is None:
            r_inv = np.diag(1.0 / sigma**2)
            self.log_det_r = self.samples * float(np.sum(np.log(2.0 * np.pi * sigma**2)))
            self.hrh = model.h.T @ r_inv @ model.h  # H^T R^-1 H (n, n)
            self.rhs = (y @ (r_inv @ model.h)).ravel()
        else:
            self.log_det_r = float(np.sum(np.log(2.0 * np.pi * self.variance)))
            self.hrh = np.einsum("ki,ij,il->kjl", 1.0 / self.variance, model.h, model.h)
            self.rhs = ((y / self.variance) @ model.h).ravel()
        self.upper = 2 * self.n - 1

    def _system(
        self, log_q: float, lam: np.ndarray, modes: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Upper band of the normal equations' matrix (LAPACK layout) for intensity q, weights
        lambda and the intervals' modes; with the increments' inverse covariances, their
        log-determinants and each interval's slice."""
        model, n, big_n = self.model, self.n, self.samples
        q = math.exp(log_q)
        qb = q * model.q_unit + process_floor(model, self.sigma, q)
        w_inv = np.linalg.inv(qb)
        log_det_qb = np.linalg.slogdet(2.0 * np.pi * qb)[1]
        phi = model.phi
        pw = np.matmul(np.swapaxes(phi, 1, 2), w_inv)  # Phi^T W per slice (S, n, n)
        pwp = np.matmul(pw, phi)  # Phi^T W Phi
        slices = model.slices(modes)

        def per_interval(a: np.ndarray) -> np.ndarray:
            """Each interval's slice of ``a`` (one slice: broadcast, not copied N times)."""
            return a[0] if a.shape[0] == 1 else a[slices]

        lam3 = lam[:, None, None]
        # blocks of the matrix: diagonal (N, n, n) and above the diagonal (N-1, n, n)
        diag = np.empty((big_n, n, n))
        diag[:] = self.hrh  # (n, n), or (N, n, n) with rows of their own noise
        diag[:-1] += lam3 * per_interval(pwp)
        diag[1:] += lam3 * per_interval(w_inv)
        off = -lam3 * per_interval(pw)
        # the LAPACK upper band in column-major order is, row by row, (N, n, 2n) in C order:
        # block k's column c holds its rows p <= c at u + p - c and the block above at
        # n - 1 + p - c (whole slices, not element scatters: 3x faster at recording scale)
        u = self.upper
        band = np.zeros((big_n, n, u + 1))
        for c in range(n):
            band[:, c, u - c : u + 1] = diag[:, : c + 1, c]
            band[1:, c, n - 1 - c : 2 * n - 1 - c] = off[:, :, c]
        ab = band.reshape(big_n * n, u + 1).T  # F-contiguous: no copy in dpbtrf
        return ab, w_inv, log_det_qb, slices

    def evaluate(
        self, log_q: float, lam: np.ndarray, modes: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """Gaussian negative log marginal likelihood of y for increments ``N(0, Qb/lambda_k)``
        (exact: ``J(x) + 1/2 log det A - N n/2 log 2 pi``), the MAP trajectory (N, n) and
        the unweighted squared Mahalanobis sizes m_k^2 (N-1,) of its increments. ``inf``
        when the normal equations are not numerically positive definite."""
        model, n, big_n = self.model, self.n, self.samples
        ab, w_inv, log_det_qb, slices = self._system(log_q, lam, modes)
        chol, info = scipy.linalg.lapack.dpbtrf(ab, lower=0, overwrite_ab=1)
        if info != 0:
            return math.inf, np.empty((0, n)), np.empty(0)
        x, info = scipy.linalg.lapack.dpbtrs(chol, self.rhs, lower=0)
        if info != 0:
            return math.inf, np.empty((0, n)), np.empty(0)
        x = x.reshape(big_n, n)
        # einsum, not matmul: BLAS threads on these tall, thin products cost more than they
        # save (3x the whole fit on a busy 2-core machine)
        resid = self.y - x[:, self.outputs]
        phi = model.phi
        if phi.shape[0] == 1:
            w = x[1:] - np.einsum("ij,kj->ki", phi[0], x[:-1])
            m2 = np.einsum("ki,ij,kj->k", w, w_inv[0], w)
            log_det_q = (big_n - 1) * log_det_qb[0]
        else:
            w = x[1:] - np.einsum("kij,kj->ki", phi[slices], x[:-1])
            m2 = np.einsum("ki,kij,kj->k", w, w_inv[slices], w)
            log_det_q = float(np.sum(log_det_qb[slices]))
        prior = float(np.dot(lam, m2)) + log_det_q - n * float(np.sum(np.log(lam)))
        nll = 0.5 * (
            float(np.sum(resid * resid / self.variance))
            + self.log_det_r
            + prior
            + 2.0 * float(np.sum(np.log(chol[-1])))
            - big_n * n * math.log(2.0 * math.pi)
        )
        if not math.isfinite(nll):
            return math.inf, np.empty((0, n)), np.empty(0)
        return float(nll), x, m2

    def information_criterion(
        self, log_q: float, lam: np.ndarray, modes: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """(AIC of the fit to the samples, trajectory (N, n), posterior variances (N, n)):
        ``chi^2 + 2 dof`` with the smoother's effective degrees of freedom ``dof = sum over
        the measured states of posterior variance / sigma^2`` (the trace of its hat matrix).
        Compares smoothers of different flexibility (Gaussian vs Student-t increments) by how
        well they predict the samples, not by their priors."""
        _, x, _ = self.evaluate(log_q, lam, modes)
        if x.size == 0:
            return math.inf, x, x
        var = self.posterior_variance(log_q, lam, modes)
        resid = self.y - x[:, self.outputs]
        chi2 = float(np.sum(resid * resid / self.variance))
        dof = float(np.sum(var[:, self.outputs] / self.variance))
        return chi2 + 2.0 * dof, x, var

    def posterior_variance(self, log_q: float, lam: np.ndarray, modes: np.ndarray) -> np.ndarray:
        """Posterior variance of every state at every sample (N, n): the diagonal of the
        inverse of the normal equations' matrix (the Laplace approximation at the MAP
        trajectory for the Student-t weights lambda), by the Takahashi recursion in the core."""
        ab, _, _, _ = self._system(log_q, lam, modes)
        chol, info = scipy.linalg.lapack.dpbtrf(ab, lower=0, overwrite_ab=1)
        if info != 0:
            return np.full((self.samples, self.n), math.nan)
        return np.asarray(_core.banded_inverse_diagonal(chol)).reshape(self.samples, self.n)


def _interval_modes(model: PairModel, x: np.ndarray) -> np.ndarray:
    """Hysteresis mode of each interval from the trajectory: sign of (input - state) at the
    interval's midpoint (mean of its end states)."""
    return model.modes(0.5 * (x[1:] + x[:-1]))


def initial_modes(model: PairModel, y: np.ndarray) -> np.ndarray:
    """Before any trajectory exists: a stage is heating while its sensor's output rises."""
    if not model.hysteretic:
        return np.zeros(y.shape[0] - 1, dtype=np.intp)
    cooling = np.diff(y, axis=0)[:, model.stage_sensor] < 0.0
    return np.sum(cooling * (1 << np.arange(model.stage_state.size)), axis=1).astype(np.intp)


class _Objective:
    """Marginal nll as a function of log q, memoised (trajectory and Mahalanobis sizes of
    every evaluated point are kept).

    Weights co-move with q: from the increments' sizes ``m2_ref`` measured at ``log_q_ref``,
    an increment keeps its size while q changes, so its squared Mahalanobis size scales as
    ``m2_ref q_ref / q`` and its weight is ``(nu + n)/(nu + m2_ref q_ref / q)``. (With fixed
    weights, q could only creep down as the steps' weights caught up, ~40 rounds.) Without a
    reference the weights are the initial ones (all 1: the Gaussian model; or those found
    with another gas model, see :func:`fit_smoother`).
    """

    def __init__(
        self, system: Trajectory, modes: np.ndarray, initial_weights: np.ndarray | None = None
    ) -> None:
        self.system = system
        self.modes = modes
        self.initial = np.ones(system.samples - 1) if initial_weights is None else initial_weights
        self.m2_ref: np.ndarray | None = None
        self.log_q_ref = 0.0
        self.cache: dict[float, tuple[float, np.ndarray, np.ndarray]] = {}

    def set(self, m2_ref: np.ndarray | None, log_q_ref: float, modes: np.ndarray) -> None:
        self.m2_ref, self.log_q_ref, self.modes = m2_ref, log_q_ref, modes
        self.cache.clear()

    def weights(self, log_q: float) -> np.ndarray:
        if self.m2_ref is None:
            return self.initial
        m2 = self.m2_ref * math.exp(self.log_q_ref - log_q)
        return (JUMP_DOF + self.system.n) / (JUMP_DOF + m2)

    def __call__(self, log_q: float) -> float:
        nll = self.result(log_q)[0]
        return nll if math.isfinite(nll) else _UNUSABLE  # optimisers need finite numbers

    def result(self, log_q: float) -> tuple[float, np.ndarray, np.ndarray]:
        if log_q not in self.cache:
            self.cache[log_q] = self.system.evaluate(log_q, self.weights(log_q), self.modes)
        return self.cache[log_q]


def _minimise_log_q(
    fun: _Objective, start: float, step: float, bounds: tuple[float, float], tol: float
) -> float:
    """Bracket the minimum of nll(log q) within ``bounds`` by walking from ``start`` in
    doubling steps, then refine with bounded Brent to ``tol``."""
    low, high = bounds
    start = min(max(start, low), high)
    f0 = fun(start)
    left, right = max(start - step, low), min(start + step, high)
    f_left, f_right = fun(left), fun(right)
    if f_left < f0 and f_left <= f_right:
        mid, f_mid, hi = left, f_left, start
        lo = left
        while lo > low:
            step *= 2.0
            lo = max(mid - step, low)
            f_lo = fun(lo)
            if f_lo >= f_mid:
                break
            hi, mid, f_mid = mid, lo, f_lo
    elif f_right < f0:
        mid, f_mid, lo = right, f_right, start
        hi = right
        while hi < high:
            step *= 2.0
            hi = min(mid + step, high)
            f_hi = fun(hi)
            if f_hi >= f_mid:
                break
            lo, mid, f_mid = mid, hi, f_hi
    else:
        lo, mid, hi = left, start, right
    if hi - lo <= tol:
        return mid
    result = scipy.optimize.minimize_scalar(
        fun, bounds=(lo, hi), method="bounded", options={"xatol": tol}
    )
    best = float(result.x)
    return best if fun(best) <= fun(mid) else mid


def _log_q_range(model: PairModel, y: np.ndarray, sigma: np.ndarray) -> tuple[float, ...]:
    """(lowest, start, highest) log q searched (rw: K^2/s, irw: K^2/s^3). Below the lowest
    the gas is constant for all the data can tell, above the highest it jumps by 1000x the
    signals' span every sample; the start lets it wander over the record by the signals'
    spread."""
    duration = model.ts * (y.shape[0] - 1)
    power = 1 if model.gas == "rw" else 3
    span = float(np.ptp(y)) + float(np.max(sigma))
    lowest = math.log((_WANDER_MIN * float(np.min(sigma))) ** 2 / duration**power)
    highest = math.log((_STEP_MAX * span) ** 2 / model.ts**power)
    spread2 = float(np.var(y[:, 0])) + float(np.sum(sigma**2))
    return lowest, math.log(spread2 / duration**power), highest


class GasFit:
    """The IRLS / marginal-likelihood alternation for one gas model, resumable.

    Start: the Gaussian model's maximum-likelihood q (all weights 1). Each round: weights
    from the increments of the current trajectory (co-moving with q, see :class:`_Objective`),
    then one safeguarded Newton step on log q from a parabola through log q and log q +- h.
    The round with the lowest nll is kept (the alternation is not a strict descent).
    """

    def __init__(
        self,
        model: PairModel,
        y: np.ndarray,
        sigma: np.ndarray,
        initial_weights: np.ndarray | None = None,
        scale: np.ndarray | None = None,
    ) -> None:
        self.model = model
        self.objective = _Objective(
            Trajectory(model, y, sigma, scale), initial_modes(model, y), initial_weights
        )
        self.tol = 1e-2 * float(np.min(sigma))  # settled: changes far below the noise
        lowest, start, highest = _log_q_range(model, y, sigma)
        self.bounds = (lowest, highest)
        # the rounds refine q: the start needs it to a factor of ~1.6 only
        self.log_q = _minimise_log_q(self.objective, start, 4.0, self.bounds, _START_TOL)
        self.nll, self.x, self.m2 = self.objective.result(self.log_q)
        self.lam = self.objective.weights(self.log_q)
        self.best = (self.nll, self.log_q, self.lam, self.objective.modes, self.x)
        self.rounds = 0
        self.mode_passes = 0
        self.converged = not math.isfinite(self.nll)

    def iterate(self, rounds: int, rival: float | None = None) -> None:
        """Up to ``rounds`` more rounds; with ``rival`` (another model's best nll) stop as
        soon as this model cannot reach it at its recent rate of improvement."""
        objective, model = self.objective, self.model
        gains = [math.inf, math.inf]
        for left in range(rounds - 1, -1, -1):
            if self.converged:
                return
            before, centre = self.best[0], self.log_q
            self._round(objective, model)
            gains = [gains[1], before - self.best[0]]
            if max(gains) < _NLL_TOL and abs(self.log_q - centre) < _LOGQ_TOL:
                self.converged = True  # statistically nothing left to gain
            if rival is not None and self.best[0] - rival > max(gains) * left:
                return

    def _round(self, objective: _Objective, model: PairModel) -> None:
        self.rounds += 1
        modes = objective.modes
        if model.hysteretic and self.mode_passes < _MAX_MODE_PASSES:
            new_modes = _interval_modes(model, self.x)
            if np.any(new_modes != modes):
                modes = new_modes
                self.mode_passes += 1
        objective.set(self.m2, self.log_q, modes)
        centre = self.log_q
        f0 = objective(centre)
        f_minus, f_plus = objective(centre - _NEWTON_H), objective(centre + _NEWTON_H)
        curvature = (f_plus - 2.0 * f0 + f_minus) / _NEWTON_H**2
        slope = (f_plus - f_minus) / (2.0 * _NEWTON_H)
        if curvature > 0.0 and math.isfinite(curvature):
            move = float(np.clip(-slope / curvature, -_NEWTON_MAX, _NEWTON_MAX))
        else:
            move = -_NEWTON_MAX if slope > 0.0 else _NEWTON_MAX
        candidates = [(f0, centre), (f_minus, centre - _NEWTON_H), (f_plus, centre + _NEWTON_H)]
        target = min(max(centre + move, self.bounds[0]), self.bounds[1])
        candidates.append((objective(target), target))
        nll, log_q = min(candidates)
        nll, x, m2 = objective.result(log_q)
        if not math.isfinite(nll):
            self.converged = True
            return
        change = float(np.sqrt(np.mean((x[:, 0] - self.x[:, 0]) ** 2)))
        self.nll, self.log_q, self.x, self.m2 = nll, log_q, x, m2
        self.lam = objective.weights(log_q)
        if nll < self.best[0]:
            self.best = (nll, log_q, self.lam, objective.modes, x)
        if change < self.tol and abs(log_q - centre) < _LOGQ_TOL:
            self.converged = True


def fit_gas_models(
    model_for: Callable[[str], PairModel], yc: np.ndarray, sigma: np.ndarray, gas: str,
    scale: np.ndarray | None = None,
) -> list[GasFit]:
    """rw first: it places the steps as single increments; irw starts from its weights (from
    all-equal weights irw smears a step into a ramp and the reweighting keeps it). ``scale``:
    the rows' noise variances over sigma^2 (:class:`Trajectory`)."""
    fits = [GasFit(model_for("rw"), yc, sigma, scale=scale)]
    fits[0].iterate(_MAX_ROUNDS)
    if gas != "rw":
        jumps = np.minimum(fits[0].best[2], 1.0)
        irw = GasFit(model_for("irw"), yc, sigma, initial_weights=jumps, scale=scale)
        irw.iterate(_MAX_ROUNDS, rival=fits[0].best[0] if gas == "auto" else None)
        fits = [*fits, irw] if gas == "auto" else [irw]
    return fits


def gaussian_log_q(system: Trajectory, modes: np.ndarray, start: float | None = None
                   ) -> tuple[float, float, np.ndarray]:
    """The Gaussian model's maximum-likelihood log q (all weights 1) for given modes, with its
    nll and MAP trajectory (from the search's memo: not evaluated again). ``start``: a log q
    found for a nearby model (other modes, other stages), searched from in small steps."""
    objective = _Objective(system, modes)
    lowest, guess, highest = _log_q_range(system.model, system.y, system.sigma)
    step = 4.0 if start is None else _NEAR_STEP
    log_q = _minimise_log_q(objective, guess if start is None else start, step,
                            (lowest, highest), _LOGQ_TOL)
    nll, x, _ = objective.result(log_q)
    return log_q, nll, x
