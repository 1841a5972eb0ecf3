"""Reference of the causal gas-temperature reconstruction (a Kalman filter), to be ported to the
C++ core (fixed memory, float and double). The state-space model is shared with the offline
smoother in :mod:`dualprobe.reconstruction`.

Everything below is the specification of the port; the code follows it line by line.

1. Continuous-time model
------------------------
State ``x = [g, (g'), z_1, ..., z_S]`` (n = 1 or 2 gas states + S sensor stages):

* gas ``g = Tg``. ``gas="rw"``: random walk (Brownian motion) ``dg = dB``.
  ``gas="irw"``: integrated random walk, ``dg = g' dt``, ``dg' = dB``. ``B`` has intensity ``q``
  (K^2/s for rw, K^2/s^3 for irw), so over one interval ``Var[g(t+Ts) - g(t)] = q Ts`` (rw).
* each sensor is a chain of first-order stages ``dz/dt = (u - z) / tau`` whose input ``u`` is the
  gas for the first stage and the previous stage's state otherwise. Sensor 1's stages come
  first, then sensor 2's, each in the order its time constants are given (for a linear
  sensor the order does not matter; with hysteresis each stage switches on its own).
  Unit static gain. Outputs ``y_i = z_(last stage of sensor i) + v_i``, ``v_i ~ N(0, sigma_i^2)``
  white, i.e. ``y = H x + v``, ``R = diag(sigma_1^2, sigma_2^2)``.
* hysteresis: stage j uses ``tau_heat[j]`` while its input is above its state and
  ``tau_cool[j]`` otherwise. Mode index ``m = sum_j 2^j [u_j < z_j]`` (bit set = cooling),
  evaluated on the state at the START of the interval (causal); 2^S precomputed models.

Written ``dx = F_m x dt + L dB`` with ``L = e_0`` (rw) or ``e_1`` (irw).

2. Exact discretisation (Van Loan, once per mode, at configuration time)
-----------------------------------------------------------------------
``M = [[-F_m, L L^T], [0, F_m^T]] * Ts``, ``E = expm(M)``, ``Phi_m = E[n:, n:]^T``,
``Qunit_m = Phi_m E[:n, n:]`` (then symmetrised). This is the exact transition and the exact
covariance of the integrated noise for unit intensity: the gas is NOT held constant over the
interval (no ZOH), and the state is the gas at the sample instant itself, so the output needs
no half-sample shift. Per interval: ``x_k = Phi_m x_(k-1) + w_k``,
``w_k ~ N(0, q Qunit_m + Qfloor)``.

``Qfloor = diag(0 for gas states; for stage j of sensor i:
FLOOR_REL sigma_i^2 + FLOOR_DYN q Qunit_0[0, 0] (Ts/tau_j)^2 / 12)`` with tau_j the stage's
heating time constant. A model-error allowance: the first term (1e-4 sigma per sample) keeps the
model proper when q -> 0, the second gives every stage the within-interval variance of a
first-order stage driven by the gas. The exact Qunit is singular to rounding in the directions
of the deeper stages (eigenvalues down to 1e-23 of the largest for two second-order sensors at
100 Hz), which would make the smoother's normal equations numerically singular (condition
number 1e15 measured; 1e11 with the floor); its effect on estimates is far below the noise.

3. Gas steps: generalised likelihood-ratio (GLR) detection (Willsky & Jones 1976)
--------------------------------------------------------------------------------
A gas step between two samples shows in ONE innovation only by ~step * Ts/tau, and its
evidence accumulates over the following samples; a Gaussian filter with a small q would lag it
by ~tau, one with a large q is noisy everywhere. So the filter keeps, for each of the last
``GLR_WINDOW`` (D) sample intervals theta (from t_(theta-1) to t_theta), the hypothesis "the
gas jumped during interval theta". A jump nu at fraction phi of the interval moves the state at
its end by ``nu expm(F_m (1 - phi) Ts) e_0`` (``e_0`` = gas level), which to O((Ts/tau)^2) is
``alpha g0 + beta g1`` with ``g0 = Phi_m e_0`` (jump at the start), ``g1 = e_0`` (at the end),
``alpha = nu (1 - phi)``, ``beta = nu phi``: linear in (alpha, beta). (One signature for an
"average" position mislocates early detections by a sample and over- or undershoots by up to
3x; measured 2.5-13 % of the sensor's RMSE on 10 Hz steps against 0.9-1.3 % with two.) Per
candidate the filter keeps the two effects on the filtered state M (2 x n, rows mu0, mu1), the
2-vector a and the symmetric 2x2 C. The filter is linear, so a jump adds
``rho^T [alpha, beta]`` to the innovations (rho = M H^T, 2 x 2), and twice the log-likelihood
ratio of the best (alpha, beta) is a chi-square with 2 dof under no jump. The jump must lie
inside its interval (0 <= phi <= 1, i.e. alpha beta >= 0; unconstrained, model errors
produce huge opposite alpha and beta that made the filter diverge with 15 % wrong cooling time
constants), so the best fit is the unconstrained ``[alpha, beta] = C^-1 a`` with statistic
``a^T C^-1 a`` when that has alpha beta >= 0 (and ``det C > GLR_SINGULAR (trace C)^2``: the two
positions are resolved), else the better of the jump at the start (``alpha = a0/C00``,
statistic ``a0^2/C00``) and at the end (``beta = a1/C11``, ``a1^2/C11``). Threshold
``h = chi2.isf(GLR_FALSE_ALARM / D, 2)``: a false alarm about once per 1e6 samples (then a
"jump" of noise size is applied, harmless).

4. Recursion (k = 0..N-1); x0, P0 given (defaults in :func:`default_initial_state`)
-----------------------------------------------------------------------------------
k = 0: ``x_p = x0``, ``P_p = P0``; k >= 1, with ``m`` = mode of ``x_(k-1)``:

    x_p = Phi_m x_(k-1),   P_p = Phi_m P_(k-1) Phi_m^T + q Qunit_m + Qfloor

Measurement update (all k), Joseph form:

    S = H P_p H^T + R,   K = P_p H^T S^-1,   e = y_k - H x_p
    x_k = x_p + K e,     P_k = (I - K H) P_p (I - K H)^T + K R K^T
    loglik += -1/2 (e^T S^-1 e + log det(2 pi S))

GLR (k >= 1, after the update; candidates oldest first):

    for each stored candidate:  M = M Phi_m^T            (before the update of step k)
    new candidate theta = k:    M = [Phi_m e_0, e_0]^T, a = 0, C = 0
                                (the oldest is dropped when D are stored)
    for every candidate:        rho = M H^T
                                a += rho S^-1 e,  C += rho S^-1 rho^T,  M = M - rho K^T
                                (stat, [alpha, beta], W) as in 3., W the inverse information:
                                C^-1, or [[1/C00, 0], [0, 0]], or [[0, 0], [0, 1/C11]]
                                (start preferred when a0^2/C00 = a1^2/C11)
    j = first candidate with the largest stat; if stat_j > h:
        x_k += alpha mu0_j + beta mu1_j,  P_k += M_j^T W_j M_j,  drop all candidates
        (jump size alpha + beta in interval theta_j, at fraction beta / (alpha + beta))

The output is ``x_k[0]``, the filtered gas temperature at the instant t_k. Memory: x (n),
P (n x n), D x (2 n + 5) for the GLR plus the constant matrices; cost per sample O(n^3 + D n^2)
with n <= 6. Time-varying gain (the GLR signatures need the actual K of each step).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.stats

__all__ = [
    "FLOOR_REL",
    "GAS_MODELS",
    "GLR_FALSE_ALARM",
    "GLR_SINGULAR",
    "GLR_WINDOW",
    "FilterResult",
    "PairModel",
    "default_initial_state",
    "glr_threshold",
    "kalman_filter",
    "pair_model",
]

GAS_MODELS = ("rw", "irw")
FLOOR_REL = 1e-8  # model-error variance per sample on each sensor stage, relative to sigma^2
FLOOR_DYN = 1.0  # ... plus this share of a first-order stage's own within-interval variance
GLR_WINDOW = 64  # candidate jump times kept; a 1 K step at 0.1 K noise is found within ~25
GLR_FALSE_ALARM = 1e-6  # probability per sample of declaring a jump that did not happen
GLR_SINGULAR = 1e-12  # det C / trace(C)^2 below this: the jump's position is not resolved yet

Taus = tuple[float, ...]


@dataclass(frozen=True, eq=False)
class PairModel:
    """Discretised model of a sensor pair seeing one gas temperature (see module docstring).

    ``phi``/``q_unit``/``jump_basis`` have one slice per hysteresis mode (a single slice
    without hysteresis); ``jump_basis[m] = [Phi_m e_0, e_0]`` (2, n), the state change from a
    unit gas jump at the start and at the end of an interval; ``stage_input[j]`` and
    ``stage_state[j]`` index the input and state of stage j in x.
    """

    ts: float
    gas: str
    taus_heat: tuple[Taus, Taus]
    taus_cool: tuple[Taus, Taus]
    phi: np.ndarray
    q_unit: np.ndarray
    jump_basis: np.ndarray
    h: np.ndarray
    stage_input: np.ndarray
    stage_state: np.ndarray
    stage_sensor: np.ndarray

    @property
    def n(self) -> int:
        return int(self.h.shape[1])

    @property
    def n_gas(self) -> int:
        return 2 if self.gas == "irw" else 1

    @property
    def hysteretic(self) -> bool:
        return self.phi.shape[0] > 1

    def floor(self, sigma: Sequence[float], q: float) -> np.ndarray:
        """The model-error floor ``Qfloor`` for noise levels ``sigma`` and gas intensity ``q``
        (see docstring, 2)."""
        taus = np.array(self.taus_heat[0] + self.taus_heat[1])
        gas_step = q * float(self.q_unit[0, 0, 0])  # variance of one gas increment
        diag = np.zeros(self.n)
        diag[self.stage_state] = (
            FLOOR_REL * np.square(np.asarray(sigma, dtype=float))[self.stage_sensor]
            + FLOOR_DYN * gas_step * (self.ts / taus) ** 2 / 12.0
        )
        return np.diag(diag)

    def modes(self, x: np.ndarray) -> np.ndarray:
        """Hysteresis mode of each state in ``x`` (..., n): bit j set when stage j cools."""
        x = np.asarray(x, dtype=float)
        if not self.hysteretic:
            return np.zeros(x.shape[:-1], dtype=np.intp)
        cooling = x[..., self.stage_input] < x[..., self.stage_state]
        return np.sum(cooling * (1 << np.arange(self.stage_state.size)), axis=-1).astype(np.intp)


def _continuous(
    gas: str, taus: Sequence[Taus], stage_taus: Sequence[float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """F, L, H and the stage index arrays for stage time constants ``stage_taus`` (flat)."""
    n_gas = 2 if gas == "irw" else 1
    n = n_gas + sum(len(t) for t in taus)
    f = np.zeros((n, n))
    noise_input = np.zeros(n)
    h = np.zeros((2, n))
    if gas == "irw":
        f[0, 1] = 1.0
        noise_input[1] = 1.0
    else:
        noise_input[0] = 1.0
    inputs, states, sensors = [], [], []
    index = n_gas
    for sensor, sensor_taus in enumerate(taus):
        source = 0
        for _ in sensor_taus:
            inputs.append(source)
            states.append(index)
            sensors.append(sensor)
            source = index
            index += 1
        h[sensor, source] = 1.0
    for j, tau in enumerate(stage_taus):
        f[states[j], inputs[j]] += 1.0 / tau
        f[states[j], states[j]] -= 1.0 / tau
    return f, noise_input, h, np.array(inputs), np.array(states), np.array(sensors)


def _van_loan(f: np.ndarray, noise_input: np.ndarray, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation: transition and unit-intensity process-noise covariance."""
    n = f.shape[0]
    big = np.zeros((2 * n, 2 * n))
    big[:n, :n] = -f
    big[:n, n:] = np.outer(noise_input, noise_input)
    big[n:, n:] = f.T
    e = scipy.linalg.expm(big * ts)
    phi = e[n:, n:].T
    q = phi @ e[:n, n:]
    return phi, 0.5 * (q + q.T)


def _check_taus(name: str, taus: Sequence[float]) -> Taus:
    values = tuple(float(t) for t in taus)
    if len(values) not in (1, 2):
        raise ValueError(f"{name}: need 1 or 2 time constants per sensor, got {len(values)}")
    if not all(math.isfinite(t) and t > 0.0 for t in values):
        raise ValueError(f"{name}: time constants must be finite and > 0, got {values}")
    return values


def pair_model(
    taus1: Sequence[float],
    taus2: Sequence[float],
    ts: float,
    *,
    gas: str = "rw",
    taus1_cool: Sequence[float] | None = None,
    taus2_cool: Sequence[float] | None = None,
) -> PairModel:
    """Build and discretise the model of section 1-2 (one slice per hysteresis mode)."""
    if not (math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"pair_model: ts must be finite and > 0, got {ts}")
    if gas not in GAS_MODELS:
        raise ValueError(f"pair_model: gas must be one of {GAS_MODELS}, got {gas!r}")
    heat = (_check_taus("taus1", taus1), _check_taus("taus2", taus2))
    cool_in = (taus1_cool, taus2_cool)
    cool = tuple(
        heat[i] if c is None else _check_taus(f"taus{i + 1}_cool", c) for i, c in enumerate(cool_in)
    )
    for i in range(2):
        if len(cool[i]) != len(heat[i]):
            raise ValueError(
                f"taus{i + 1}_cool: need {len(heat[i])} time constants like taus{i + 1}, "
                f"got {len(cool[i])}"
            )
    cool_pair: tuple[Taus, Taus] = (cool[0], cool[1])
    flat_heat = heat[0] + heat[1]
    flat_cool = cool_pair[0] + cool_pair[1]
    hysteretic = flat_heat != flat_cool
    n_modes = 1 << len(flat_heat) if hysteretic else 1
    phis, qs = [], []
    h = inputs = states = sensors = np.empty(0)
    for mode in range(n_modes):
        stage_taus = [
            flat_cool[j] if (mode >> j) & 1 else flat_heat[j] for j in range(len(flat_heat))
        ]
        f, noise_input, h, inputs, states, sensors = _continuous(gas, heat, stage_taus)
        phi, q = _van_loan(f, noise_input, ts)
        phis.append(phi)
        qs.append(q)
    phi_all = np.array(phis)
    level = np.zeros(phi_all.shape[1])
    level[0] = 1.0
    # a unit gas jump at the start of the interval (Phi e_0) and at its end (e_0)
    basis = np.stack([phi_all[:, :, 0], np.broadcast_to(level, phi_all.shape[:2])], axis=1)
    return PairModel(
        ts=float(ts),
        gas=gas,
        taus_heat=heat,
        taus_cool=cool_pair,
        phi=phi_all,
        q_unit=np.array(qs),
        jump_basis=basis,
        h=h,
        stage_input=inputs,
        stage_state=states,
        stage_sensor=sensors,
    )


def default_initial_state(
    model: PairModel, y0: Sequence[float], sigma: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Initial state and covariance from the first sample pair ``y0``.

    Every stage of sensor i starts at y_i(0), the gas at their mean, its slope at 0. The
    spread is wide enough not to bias the start: gas standard deviation
    ``SPREAD_GAS = 100 (|y1(0) - y2(0)| + sigma1 + sigma2 + 1 K)``, a non-measured stage the
    same, a measured stage ``sigma_i`` plus the same spread, the irw slope that spread per
    smallest time constant.
    """
    y = np.asarray(y0, dtype=float)
    s = np.asarray(sigma, dtype=float)
    spread = 100.0 * (abs(float(y[0] - y[1])) + float(s[0] + s[1]) + 1.0)
    x0 = np.zeros(model.n)
    var = np.zeros(model.n)
    x0[0] = 0.5 * float(y[0] + y[1])
    var[0] = spread**2
    if model.n_gas == 2:
        tau_min = min(min(model.taus_heat[0]), min(model.taus_heat[1]))
        var[1] = (spread / tau_min) ** 2
    x0[model.stage_state] = y[model.stage_sensor]
    var[model.stage_state] = spread**2
    measured = np.flatnonzero(model.h.any(axis=0))
    var[measured] = s[np.argmax(model.h[:, measured], axis=0)] ** 2
    return x0, np.diag(var)


@dataclass(frozen=True, eq=False)
class FilterResult:
    """Filtered states (N, n), the gas entry of their covariances (N,), innovations (N, 2),
    the sample indices at which a jump was declared with the interval it was placed in and
    its size, and the innovation log-likelihood."""

    states: np.ndarray
    gas_variance: np.ndarray
    innovations: np.ndarray
    jump_detected_at: np.ndarray
    jump_interval: np.ndarray
    jump_size: np.ndarray
    log_likelihood: float

    @property
    def gas(self) -> np.ndarray:
        return self.states[:, 0]


def glr_threshold(window: int = GLR_WINDOW, false_alarm: float = GLR_FALSE_ALARM) -> float:
    """Detection threshold on a^T C^-1 a: chi-square (2 dof) upper quantile at
    false_alarm/window."""
    return float(scipy.stats.chi2.isf(false_alarm / window, 2))


def _glr_statistics(a: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per candidate: the statistic, the maximum-likelihood (alpha, beta) with the jump inside
    its interval (alpha beta >= 0), and the inverse information matrix of that estimate."""
    count = a.shape[0]
    c00, c11 = c[:, 0, 0], c[:, 1, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        stat0 = np.where(c00 > 0.0, a[:, 0] ** 2 / c00, 0.0)  # jump at the start (beta = 0)
        stat1 = np.where(c11 > 0.0, a[:, 1] ** 2 / c11, 0.0)  # jump at the end (alpha = 0)
    stat = np.maximum(stat0, stat1)
    coef = np.zeros((count, 2))
    weight = np.zeros((count, 2, 2))
    at_start = stat0 >= stat1
    if np.any(at_start):
        coef[at_start, 0] = a[at_start, 0] / c00[at_start]
        weight[at_start, 0, 0] = 1.0 / c00[at_start]
    at_end = ~at_start & (c11 > 0.0)
    if np.any(at_end):
        coef[at_end, 1] = a[at_end, 1] / c11[at_end]
        weight[at_end, 1, 1] = 1.0 / c11[at_end]
    det = c00 * c11 - c[:, 0, 1] * c[:, 1, 0]
    resolved = det > GLR_SINGULAR * (c00 + c11) ** 2
    if np.any(resolved):
        inv = np.linalg.inv(c[resolved])
        sol = np.einsum("dij,dj->di", inv, a[resolved])
        inside = sol[:, 0] * sol[:, 1] >= 0.0  # 0 <= phi <= 1
        idx = np.flatnonzero(resolved)[inside]
        stat[idx] = np.sum(a[idx] * sol[inside], axis=1)
        coef[idx] = sol[inside]
        weight[idx] = inv[inside]
    return stat, coef, weight


def kalman_filter(
    y: np.ndarray,
    model: PairModel,
    q: float,
    sigma: Sequence[float],
    *,
    detect_jumps: bool = True,
    window: int = GLR_WINDOW,
    x0: np.ndarray | None = None,
    p0: np.ndarray | None = None,
) -> FilterResult:
    """Causal filter of sections 3-4 on the samples ``y`` (N, 2). ``q`` is the gas intensity,
    ``sigma`` the two noise standard deviations (> 0); ``detect_jumps=False`` gives the plain
    Gaussian Kalman filter."""
    y = np.asarray(y, dtype=float)
    if y.ndim != 2 or y.shape[1] != 2 or y.shape[0] < 1:
        raise ValueError(f"kalman_filter: y must have shape (N, 2), got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise ValueError("kalman_filter: y must be finite")
    sig = np.asarray(sigma, dtype=float)
    if sig.shape != (2,) or not np.all(np.isfinite(sig)) or np.any(sig <= 0.0):
        raise ValueError(f"kalman_filter: sigma must be two values > 0, got {sigma}")
    if not (math.isfinite(q) and q >= 0.0):
        raise ValueError(f"kalman_filter: q must be finite and >= 0, got {q}")
    if window < 1:
        raise ValueError(f"kalman_filter: window must be >= 1, got {window}")
    if x0 is None or p0 is None:
        dx0, dp0 = default_initial_state(model, y[0], sig)
        x0 = dx0 if x0 is None else x0
        p0 = dp0 if p0 is None else p0
    n = model.n
    h = model.h
    r = np.diag(sig**2)
    process = q * model.q_unit + model.floor(sig, q)  # (modes, n, n)
    identity = np.eye(n)
    threshold = glr_threshold(window)
    big_n = y.shape[0]
    states = np.empty((big_n, n))
    gas_var = np.empty(big_n)
    innovations = np.empty((big_n, 2))
    detected: list[tuple[int, int, float]] = []
    # GLR candidates, oldest first: effects (2, n) on the filtered state, a (2), C (2, 2)
    eff = np.empty((0, 2, n))
    a_sum = np.empty((0, 2))
    c_sum = np.empty((0, 2, 2))
    theta = np.empty(0, dtype=np.intp)
    loglik = 0.0
    x = np.asarray(x0, dtype=float).copy()
    p = np.asarray(p0, dtype=float).copy()
    for k in range(big_n):
        if k == 0:
            x_p, p_p = x, p
        else:
            m = int(model.modes(x)) if model.hysteretic else 0
            phi = model.phi[m]
            x_p = phi @ x
            p_p = phi @ p @ phi.T + process[m]
            if detect_jumps:
                keep = slice(max(0, theta.size - window + 1), None)
                eff = np.concatenate([eff[keep] @ phi.T, model.jump_basis[m][None]])
                a_sum = np.concatenate([a_sum[keep], np.zeros((1, 2))])
                c_sum = np.concatenate([c_sum[keep], np.zeros((1, 2, 2))])
                theta = np.append(theta[keep], k)
        s = h @ p_p @ h.T + r
        s_inv = np.linalg.inv(s)
        gain = p_p @ h.T @ s_inv
        e = y[k] - h @ x_p
        x = x_p + gain @ e
        ikh = identity - gain @ h
        p = ikh @ p_p @ ikh.T + gain @ r @ gain.T
        loglik -= 0.5 * float(e @ s_inv @ e + np.log(np.linalg.det(2.0 * np.pi * s)))
        if detect_jumps and k > 0:
            rho = eff @ h.T  # (candidates, 2, 2): innovation signatures
            a_sum = a_sum + rho @ (s_inv @ e)
            c_sum = c_sum + rho @ s_inv @ np.swapaxes(rho, 1, 2)
            eff = eff - rho @ gain.T
            stat, coef, weight = _glr_statistics(a_sum, c_sum)
            j = int(np.argmax(stat))
            if stat[j] > threshold:
                alpha_beta = coef[j]
                x = x + alpha_beta @ eff[j]
                p = p + eff[j].T @ weight[j] @ eff[j]
                detected.append((k, int(theta[j]), float(np.sum(alpha_beta))))
                eff = np.empty((0, 2, n))
                a_sum = np.empty((0, 2))
                c_sum = np.empty((0, 2, 2))
                theta = np.empty(0, dtype=np.intp)
        states[k] = x
        gas_var[k] = p[0, 0]
        innovations[k] = e
    found = np.array(detected, dtype=float).reshape(-1, 3)
    return FilterResult(
        states=states,
        gas_variance=gas_var,
        innovations=innovations,
        jump_detected_at=found[:, 0].astype(np.intp),
        jump_interval=found[:, 1].astype(np.intp),
        jump_size=found[:, 2],
        log_likelihood=loglik,
    )
