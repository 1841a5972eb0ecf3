"""A lower bound on the RMSE of ANY causal reconstruction on the drive-cycle scenario (issue 13's
"causal within 2x of the offline smoother"), by a genie argument.

Give the estimator, for free, the true sensor models at every tick and the gas's slow part
(everything of ``dualprobe.simulate.drive_cycle`` except its fluctuation). What is left to
estimate is the fluctuation: white Gaussian noise through the simulator's band filter (2nd-order
Butterworth, an octave either side of ``fluctuation_hz``, scaled to ``fluctuation_std``, on its
fine grid), seen through the two-stage sensors plus white measurement noise. That is a linear
Gaussian state-space model, for which the Kalman filter is the minimum-mean-square-error
estimator among all causal estimators, linear or not; its error variance follows from the
Riccati recursion alone (no data). A real estimator, which must also find the slow part, can only
do worse: the filter's RMSE bounds every causal method from below. The RTS smoother on the same
model gives the offline counterpart, for scale.

Approximations (each small against the bound's margin, see firmware_sim/README.md): the gas is
held over each fine step (the simulator interpolates it linearly), and each tick's time
constants are held over the tick's fine steps.
"""

from __future__ import annotations

import inspect

import numpy as np
import scipy.linalg
import scipy.signal


def fluctuation_model(simulate) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """(A, B, gas row over [x, w], input variance, fine step) of the simulator's fluctuation."""
    defaults = inspect.signature(simulate.drive_cycle).parameters
    dt = float(defaults["dt"].default)
    hz = float(defaults["fluctuation_hz"].default)
    std = float(defaults["fluctuation_std"].default)
    nyq = 0.5 / dt
    b, a = scipy.signal.butter(2, [0.5 * hz / nyq, min(2.0 * hz / nyq, 0.99)], "band")
    fa, fb, fc, fd = scipy.signal.tf2ss(b, a)
    stationary = scipy.linalg.solve_discrete_lyapunov(fa, fb @ fb.T)
    unit_var = (fc @ stationary @ fc.T + fd @ fd.T).item()
    gas = np.concatenate([fc[0], fd[0]])
    return fa, fb[:, 0], gas, std * std / unit_var, dt


def fine_step(fa, fb, gas, dt, taus1, taus2) -> np.ndarray:
    """Transition over one fine step of [x (band filter), w (its input), sheath1, element1,
    sheath2, element2]; taus are (element, sheath)."""
    nb = fa.shape[0]
    n = nb + 5
    f = np.zeros((n, n))
    f[:nb, :nb] = fa
    f[:nb, nb] = fb
    row = np.zeros(n)
    row[: nb + 1] = gas
    index = nb + 1
    for element, sheath in (taus1, taus2):
        es, ee = np.exp(-dt / sheath), np.exp(-dt / element)
        coupling = sheath * (es - ee) / (sheath - element)  # sheath's start -> element's end
        f[index, index] = es
        f[index] += (1.0 - es) * row
        f[index + 1, index + 1] = ee
        f[index + 1, index] += coupling
        f[index + 1] += (1.0 - ee - coupling) * row
        index += 2
    return f


def causal_bound(truth: dict, simulate) -> tuple[np.ndarray, np.ndarray]:
    """Per-tick error variances of the genie's filter (the causal bound) and of its smoother."""
    fa, fb, gas_fine, q, dt = fluctuation_model(simulate)
    ts = float(truth["ts"])
    steps = round(ts / dt)
    taus1, taus2 = np.asarray(truth["true_taus1"]), np.asarray(truth["true_taus2"])
    nb = fa.shape[0]
    n = nb + 5
    gas = np.zeros(n)
    gas[: nb + 1] = gas_fine
    h = np.zeros((2, n))
    h[0, nb + 2] = 1.0
    h[1, nb + 4] = 1.0
    r = np.diag([float(truth["sigma1"]) ** 2, float(truth["sigma2"]) ** 2])
    ticks = taus1.shape[0]
    p = np.zeros((n, n))  # stationary fluctuation; sensors start at the gas, known
    p[:nb, :nb] = q * scipy.linalg.solve_discrete_lyapunov(fa, np.outer(fb, fb))
    p[nb, nb] = q
    filtered, predicted, transitions = [], [], []
    for k in range(ticks):
        if k > 0:
            fine = fine_step(fa, fb, gas_fine, dt, taus1[k - 1], taus2[k - 1])
            phi = np.eye(n)
            noise = np.zeros((n, n))
            for _ in range(steps):
                phi = fine @ phi
                noise = fine @ noise @ fine.T
                noise[nb, nb] += q  # the band filter's new input
            p = phi @ p @ phi.T + noise
            transitions.append(phi)
        predicted.append(p)
        gain = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
        p = p - gain @ h @ p
        p = 0.5 * (p + p.T)
        filtered.append(p)
    var_f = np.array([gas @ pk @ gas for pk in filtered])
    var_s = np.empty(ticks)
    ps = filtered[-1]
    var_s[-1] = gas @ ps @ gas
    for k in range(ticks - 2, -1, -1):
        c = filtered[k] @ transitions[k].T @ np.linalg.inv(predicted[k + 1])
        ps = filtered[k] + c @ (ps - predicted[k + 1]) @ c.T
        var_s[k] = gas @ ps @ gas
    return var_f, var_s
