"""The offline heavy-tailed MAP smoother (:func:`fit_smoother`): rw or irw gas by marginal
likelihood, the noise raised where the model needs runs of jumps, and gas steps that sit on a
sample instant (see the :mod:`dualprobe.reconstruction` docstring)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from dualprobe.models.jitter import row_noise_scale
from dualprobe.reconstruction.checks import as_sigma, as_taus, check_signals, effective_sigma
from dualprobe.reconstruction.stages import resolvable_stages, unresolved_lag
from dualprobe.reconstruction.statespace import (
    GAS_MODELS,
    PairModel,
    continuous_matrix,
    pair_model,
)
from dualprobe.reconstruction.trajectory import (
    JUMP_DOF,
    Trajectory,
    fit_gas_models,
    gaussian_log_q,
    initial_modes,
)

__all__ = ["TUNE_ROWS", "SmootherFit", "fit_smoother", "rescheduled_gas"]

_JUMP_WEIGHT = 1e-2  # an interval weighted below this share of the median holds a jump
_STEP_FRACTIONS = 41  # positions inside an interval tried for a step (every 2.5 %)
_MAX_JUMP_REGION = 4  # longer runs of jump intervals are not one step on an instant
_MAX_MODE_PASSES = 6  # hysteresis: re-evaluations of the switching modes
_MAX_NOISE_RAISES = 6  # refits with the noise level raised (see fit_smoother)
_NOISE_RAISE = 10.0  # factor per refit
_SNAP = 4  # grid points (10 % of Ts): a step this close to an instant sits on it
_GRID_CHI2 = 6.635  # chi2(1 dof) 99 % quantile: the step-at-a-sample tests
# Longer records: the gas model, its intensity and the noise levels are tuned on the most
# active block of this many rows and applied to the whole (the tuning takes ~140 banded solves;
# 20 000 rows are minutes of data at 100 Hz, far more than the intensity needs)
TUNE_ROWS = 20_000
_APPLY_ROUNDS = 12  # reweighting solves on the whole record (settles in 4-8)


@dataclass(frozen=True, eq=False)
class SmootherFit:
    """Outcome of :func:`fit_smoother`: the chosen model, gas intensity ``q`` (scale of the
    Student-t increments), per-interval weights lambda (N-1,), hysteresis modes (N-1,), the
    MAP state trajectory (N, n; offset removed: add ``offset``), the marginal nll, the noise
    levels used, and the candidates' nll by gas model."""

    model: PairModel
    q: float
    weights: np.ndarray
    modes: np.ndarray
    states: np.ndarray
    offset: float
    nll: float
    sigma: tuple[float, float]
    nll_by_gas: dict[str, float]
    iterations: int
    steps_at_samples: np.ndarray
    gas_variance: np.ndarray  # posterior variance of the gas at each sample (Laplace, at the MAP)
    increments: str = "student_t"  # or "gaussian"
    noise_scale: np.ndarray | None = None  # (N, 2) rows' noise variance over sigma^2 (jitter)

    @property
    def gas(self) -> np.ndarray:
        """MAP gas temperature at the sample instants, right-continuous where a gas step sits
        on an instant (``steps_at_samples`` rows (k0, k1, m): the level of sample k0 before
        the instant k0 + m, that of sample k1 from it on)."""
        gas = self.states[:, 0] + self.offset
        for k0, k1, m in self.steps_at_samples:
            gas[k0 + 1 : k0 + m] = gas[k0]
            gas[k0 + m : k1] = gas[k1]
        return gas

    @property
    def gas_std(self) -> np.ndarray:
        """Posterior standard deviation of the gas at the sample instants (given the model)."""
        return np.sqrt(np.maximum(self.gas_variance, 0.0))

    @property
    def background_q(self) -> float:
        """Intensity of the ordinary (non-jump) gas motion: q / median weight."""
        return self.q / float(np.median(self.weights))


def _steps_at_samples(
    model: PairModel,
    y: np.ndarray,
    x: np.ndarray,
    lam: np.ndarray,
    modes: np.ndarray,
    sigma: np.ndarray,
) -> np.ndarray:
    """Gas steps that sit exactly on a sample instant: rows (first sample, last sample, m) of
    the jump regions whose step is at the instant first + m (see the module docstring,
    "Steps on a sample instant").

    A jump region is a run of intervals k0..k1 the smoother weights below ``_JUMP_WEIGHT``
    of the median. One step J = g(k1+1) - g(k0) at t(k0) + s Ts, s in [0, L] (L = k1-k0+1),
    from the state x(k0) predicts the outputs at t(k0+1..k0+L) as the free response plus
    ``J H expm(F (j - s) Ts) e_0`` (j > s). Misfit ``r(s) = sum (residual / sigma)^2 / 2``
    (the halving: the sample's and the smoothed state's errors) over a grid of s. Accepted
    at the instant m nearest the best s when m is as good (``2 (r(m) - min r) <=
    chi2_1(0.99)``) or within ``_SNAP`` grid points of it (a slightly wrong time constant
    shifts the best s by a few % of Ts), and every other instant is clearly worse
    (``2 (r - r(m)) > chi2_1(0.99)``: no step, or a step nowhere in particular)."""
    found: list[tuple[int, int, int]] = []
    if model.scheduled:
        # time constants that follow the flow: the step response is not one shape; a step on
        # an instant stays as the smoother placed it (off-grid convention)
        return np.zeros((0, 3), dtype=np.intp)
    slices = model.slices(modes)
    jump = lam < _JUMP_WEIGHT * float(np.median(lam)) if lam.size else np.zeros(0, bool)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], jump.astype(np.int8), [0]))))
    regions = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    regions = [(a, b) for a, b in regions if b - a <= _MAX_JUMP_REGION]
    if not regions:
        return np.zeros((0, 3), dtype=np.intp)
    per = _STEP_FRACTIONS - 1  # grid points per sample interval
    longest = max(b - a for a, b in regions)
    f_ts = continuous_matrix(model) * model.ts
    # output response to a unit step i/per intervals ago, i = 0 .. longest * per
    # powers of one grid step's transition (one expm, not one per grid point)
    step_matrix = scipy.linalg.expm(f_ts / per)
    state = np.zeros(step_matrix.shape[0])
    state[0] = 1.0
    response = np.empty((longest * per + 1, model.h.shape[0]))
    for i in range(response.shape[0]):
        response[i] = model.h @ state
        state = step_matrix @ state
    for k0, end in regions:
        length = end - k0
        step = x[end, 0] - x[k0, 0]
        free = x[k0].copy()
        r = np.zeros(length * per + 1)  # s = i / per, i = 0 .. length * per
        positions = np.arange(r.size)
        for j in range(1, length + 1):
            free = model.phi[slices[k0 + j - 1]] @ free
            resid = y[k0 + j] - model.h @ free
            ago = j * per - positions  # (j - s) in grid units, > 0 when the step came first
            effect = np.where((ago > 0)[:, None], step * response[np.maximum(ago, 0)], 0.0)
            r += 0.5 * np.sum(((resid - effect) / sigma) ** 2, axis=1)
        on_instant = r[::per]
        best = int(np.argmin(r))
        m = round(best / per)
        others = np.delete(on_instant, m)
        near = 2.0 * (on_instant[m] - r[best]) <= _GRID_CHI2 or abs(best - m * per) <= _SNAP
        if near and (others.size == 0 or 2.0 * (np.min(others) - on_instant[m]) > _GRID_CHI2):
            found.append((k0, end, m))
    return np.array(found, dtype=np.intp).reshape(-1, 3)


def _gaussian_fit(
    model_for: Callable[[str], PairModel], yc: np.ndarray, sigma: np.ndarray, gas: str,
    offset: float, scale: np.ndarray | None = None, start: float | None = None,
) -> SmootherFit:
    """The Gaussian-increment smoother (the RTS smoother's mean): each gas model at its
    maximum-likelihood intensity, the better marginal likelihood (exact) wins. ``start``: the
    log q of a nearby model (with ``gas`` one model) to search from."""
    best: tuple[float, float, PairModel, np.ndarray, np.ndarray, Trajectory] | None = None
    nll_by_gas = {}
    for name in (("rw", "irw") if gas == "auto" else (gas,)):
        model = model_for(name)
        system = Trajectory(model, yc, sigma, scale)
        modes = np.zeros(yc.shape[0] - 1, dtype=np.intp)
        log_q = start
        for _ in range(_MAX_MODE_PASSES if model.hysteretic else 1):
            # a later pass (modes moved) starts from the last pass's intensity
            log_q, nll, x = gaussian_log_q(system, modes, log_q)
            new = model.modes(0.5 * (x[1:] + x[:-1])) if x.size else modes
            if np.array_equal(new, modes):
                break
            modes = new
        nll_by_gas[name] = nll
        if best is None or nll < best[0]:
            best = (nll, log_q, model, modes, x, system)
    assert best is not None
    nll, log_q, model, modes, x, system = best
    if not math.isfinite(nll):
        raise ValueError("reconstruct_pair: the smoother found no usable gas intensity")
    ones = np.ones(yc.shape[0] - 1)
    return SmootherFit(
        model=model, q=math.exp(log_q), weights=ones, modes=modes, states=x, offset=offset,
        nll=nll, sigma=(float(sigma[0]), float(sigma[1])), nll_by_gas=nll_by_gas,
        iterations=0, steps_at_samples=np.zeros((0, 3), dtype=np.intp),
        gas_variance=system.posterior_variance(log_q, ones, modes)[:, 0],
        increments="gaussian", noise_scale=scale,
    )


def _fast_first(
    heat: tuple[float, ...], cool: tuple[float, ...]
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A sensor's stages with the fastest in front, where the gas meets it (a sheath before the
    element): the measured stage is then the slow one, whose model-error floor (a share of the
    gas move reaching it within an interval) is small. Largest first put the floor of a 0.3 s
    sheath on the measured output and cost 30 % of RMSE on sheathed drive cycles."""
    if len(heat) < 2 or heat[0] <= heat[1]:
        return heat, cool
    return heat[::-1], cool[::-1]


def _longest_jump_run(lam: np.ndarray) -> int:
    """Most consecutive intervals weighted as jumps (below ``_JUMP_WEIGHT`` of the median)."""
    if lam.size == 0:
        return 0
    jump = np.concatenate(([0], (lam < _JUMP_WEIGHT * float(np.median(lam))).astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(jump))
    return int(np.max(edges[1::2] - edges[::2])) if edges.size else 0


def fit_smoother(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    taus1: float | Sequence[float],
    taus2: float | Sequence[float],
    *,
    noise_std: float | Sequence[float] | None = None,
    taus1_cool: float | Sequence[float] | None = None,
    taus2_cool: float | Sequence[float] | None = None,
    gas: str = "auto",
    schedule: np.ndarray | None = None,
    increments: str = "auto",
    near: SmootherFit | None = None,
) -> SmootherFit:
    """Fit the heavy-tailed smoother (module docstring) and return everything it found.

    ``gas``: ``"auto"`` (rw or irw by marginal likelihood), ``"rw"`` or ``"irw"``.
    ``schedule`` (N,): the time constants in effect at sample k are the given ones times
    ``schedule[k]`` (time constants that follow the gas flow; interval k uses the mean of its
    two ends). ``increments``: "student_t" (heavy tails: steps stay sharp), "gaussian" (the
    RTS smoother's prior: a gas that moves continuously) or "auto": Gaussian with a schedule.
    Field conditions, where time constants follow the flow, have a gas that follows engine
    load through combustion and manifold lags: fast but never a step. There the Student-t
    increments place "jumps" whose size and instant the samples hardly fix (119 on a
    20-minute simulated drive cycle, the gas 3.9 K RMS off around them; with Gaussian
    increments 1.07 K overall against the oracle's 1.03 K).
    ``near``: a fit of the same data with nearby time constants (its stages moved by their
    uncertainty): its gas model is kept and, with Gaussian increments, the intensity is
    searched from its own (9 banded solves instead of 28 for both gas models from afar on a
    30 min sheathed drive cycle).
    """
    y = check_signals(t1, t2, ts)
    taus = (as_taus("taus1", taus1), as_taus("taus2", taus2))
    if taus[0] is None or taus[1] is None:
        raise ValueError("reconstruct_pair: taus1 and taus2 are required")
    cool = (as_taus("taus1_cool", taus1_cool), as_taus("taus2_cool", taus2_cool))
    if gas != "auto" and gas not in GAS_MODELS:
        raise ValueError(f"fit_smoother: gas must be auto, rw or irw, got {gas!r}")
    sigma = effective_sigma(y, as_sigma(noise_std))
    offset = float(np.mean(y))
    yc = y - offset  # states relative to the record's mean: better conditioned sums
    intervals = None
    resolution = float(ts)  # stages are resolvable relative to this (the fastest schedule's)
    if schedule is not None:
        row = np.asarray(schedule, dtype=float)
        if row.shape != (y.shape[0],) or not np.all(np.isfinite(row)) or np.any(row <= 0.0):
            raise ValueError("reconstruct_pair: schedule must be finite, > 0, one per sample")
        intervals = 0.5 * (row[1:] + row[:-1])
        resolution = float(ts) / float(np.min(row))
    stages = [_fast_first(*resolvable_stages(taus[i], resolution, cool[i])) for i in range(2)]
    for i in range(2):
        # a merged or raised stage errs by ~ its lag times the output's rate: noise to the model
        rate = float(np.sqrt(np.mean(np.diff(y[:, i]) ** 2))) / float(ts)
        sigma[i] = math.hypot(sigma[i], unresolved_lag(taus[i], cool[i], resolution) * rate)

    def models(part: slice | None = None) -> Callable[[str], PairModel]:
        scheduled = None if intervals is None or part is None else intervals[
            part.start : part.stop - 1]
        return lambda name: pair_model(
            stages[0][0],
            stages[1][0],
            float(ts),
            gas=name,
            taus1_cool=stages[0][1],
            taus2_cool=stages[1][1],
            schedule=intervals if part is None else scheduled,
        )

    if increments == "auto":
        increments = "gaussian" if schedule is not None else "student_t"
    start = None
    if near is not None:
        gas, start = near.model.gas, math.log(near.q)
    # a jittered clock: each row's noise grows with the sensor's slope (models/jitter.py),
    # and a gas fitted with one noise level follows those errors where the sensors move
    scale = row_noise_scale(y, float(ts))
    if yc.shape[0] <= TUNE_ROWS:
        return _fit(models(), yc, sigma, gas, offset, increments, scale, start)
    # recording scale: tune on a block, apply to the whole (cost linear in the length)
    block = _tuning_block(yc, TUNE_ROWS)
    tuned = _fit(models(block), yc[block], sigma, gas, offset, increments,
                 None if scale is None else scale[block], start)
    return _apply(tuned, models()(tuned.model.gas), yc, offset, scale)


def _fit(model_for: Callable[[str], PairModel], yc: np.ndarray, sigma: np.ndarray, gas: str,
         offset: float, increments: str, scale: np.ndarray | None = None,
         start: float | None = None) -> SmootherFit:
    """The whole fit (gas model, intensity, weights, noise raises) on ``yc``; ``scale``: the
    rows' noise variances over sigma^2; ``start``: a nearby fit's log q (Gaussian only)."""
    if increments == "gaussian":
        return _gaussian_fit(model_for, yc, sigma, gas, offset, scale, start)
    for _ in range(_MAX_NOISE_RAISES + 1):
        fits = fit_gas_models(model_for, yc, sigma, gas, scale)
        chosen = min(fits, key=lambda f: f.best[0])
        nll, log_q, lam, modes, x = chosen.best
        if not math.isfinite(nll):
            raise ValueError("reconstruct_pair: the smoother found no usable gas intensity")
        if _longest_jump_run(lam) <= _MAX_JUMP_REGION:
            break
        # the model needs runs of jumps: it disagrees with the samples by more than the
        # noise (e.g. time constants a little off on noise-free data); that is noise to it
        sigma = sigma * _NOISE_RAISE
    system = chosen.objective.system
    variance = system.posterior_variance(log_q, lam, modes)
    return SmootherFit(
        model=chosen.model,
        q=math.exp(log_q),
        weights=lam,
        modes=modes,
        states=x,
        offset=offset,
        nll=nll,
        sigma=(float(sigma[0]), float(sigma[1])),
        nll_by_gas={f.model.gas: f.best[0] for f in fits},
        iterations=chosen.rounds,
        steps_at_samples=_steps_at_samples(chosen.model, yc, x, lam, modes, sigma),
        gas_variance=variance[:, 0], noise_scale=scale,
    )


def rescheduled_gas(fit: SmootherFit, y: np.ndarray, schedule: np.ndarray) -> np.ndarray:
    """The gas of ``fit`` (its stages, gas model, intensity, noise levels, weights and modes
    held) on ``y`` (N, 2; as fitted) with the time constants on another ``schedule`` (N,):
    how the reconstruction moves with the schedule, one banded solve."""
    row = np.asarray(schedule, dtype=float)
    model = fit.model
    cool = model.taus_cool if model.hysteretic else (None, None)
    moved = pair_model(model.taus_heat[0], model.taus_heat[1], model.ts, gas=model.gas,
                       taus1_cool=cool[0], taus2_cool=cool[1],
                       schedule=0.5 * (row[1:] + row[:-1]))
    system = Trajectory(moved, y - fit.offset, np.asarray(fit.sigma, dtype=float),
                        fit.noise_scale)
    nll, x, _ = system.evaluate(math.log(fit.q), fit.weights, fit.modes)
    if not math.isfinite(nll):
        raise ValueError("reconstruct_pair: the smoother failed on the moved schedule")
    return x[:, 0] + fit.offset


def _tuning_block(y: np.ndarray, rows: int) -> slice:
    """The block of ``rows`` samples where the sensors move most (summed absolute changes):
    the gas model and its intensity are judged where the data say most about them. A quiet
    block would under-rate the intensity and over-smooth the active rest; an active one can
    only over-rate it (a noisier, still unbiased reconstruction, its std reported)."""
    activity = np.concatenate(([0.0], np.cumsum(np.sum(np.abs(np.diff(y, axis=0)), axis=1))))
    starts = np.arange(0, y.shape[0] - rows + 1, max(rows // 4, 1))
    totals = activity[starts + rows - 1] - activity[starts]
    start = int(starts[int(np.argmax(totals))])
    return slice(start, start + rows)


def _apply(tuned: SmootherFit, model: PairModel, yc: np.ndarray, offset: float,
           scale: np.ndarray | None = None) -> SmootherFit:
    """The tuned smoother on the whole record: its gas model, intensity and noise levels
    fixed; the Student-t weights (and hysteresis modes) re-found by iteratively reweighted
    solves, one banded solve each, until the trajectory settles far below the noise."""
    sigma = np.asarray(tuned.sigma, dtype=float)
    system = Trajectory(model, yc, sigma, scale)
    log_q = math.log(tuned.q)
    modes = initial_modes(model, yc)
    lam = np.ones(yc.shape[0] - 1)
    student = tuned.increments == "student_t"
    tol = 1e-2 * float(np.min(sigma))
    previous: np.ndarray | None = None
    rounds = _APPLY_ROUNDS
    for rounds in range(1, _APPLY_ROUNDS + 1):  # noqa: B007 (the count is reported)
        nll, x, m2 = system.evaluate(log_q, lam, modes)
        if not math.isfinite(nll):
            raise ValueError("reconstruct_pair: the smoother found no usable gas intensity")
        new_modes = model.modes(0.5 * (x[1:] + x[:-1])) if model.hysteretic else modes
        settled = previous is not None and float(
            np.sqrt(np.mean((x[:, 0] - previous[:, 0]) ** 2))) < tol
        if (settled or not student) and np.array_equal(new_modes, modes):
            break
        previous, modes = x, new_modes
        if student:
            lam = (JUMP_DOF + model.n) / (JUMP_DOF + m2)
    steps = (_steps_at_samples(model, yc, x, lam, modes, sigma) if student
             else np.zeros((0, 3), dtype=np.intp))
    return SmootherFit(
        model=model, q=tuned.q, weights=lam, modes=modes, states=x, offset=offset, nll=nll,
        sigma=tuned.sigma, nll_by_gas=tuned.nll_by_gas, iterations=tuned.iterations + rounds,
        steps_at_samples=steps,
        gas_variance=system.posterior_variance(log_q, lam, modes)[:, 0],
        increments=tuned.increments, noise_scale=scale,
    )
