"""Exact discretisation of ``K exp(-theta s) / prod(1 + tau_i s)`` for an input linear (FOH) or
constant (ZOH) between samples, and the simulation of a model or a fit (``compare``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from scipy import linalg, signal

from dualprobe.identify.result import HOLDS, Hold, TfFit

__all__ = ["as_signal", "check_ts", "responses", "simulate_fit", "simulate_model"]


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
    tiny = np.where(small, z, 0.0)  # the series only where it is used (z*z overflows far out)
    phi1 = np.where(small, 1.0 + tiny / 2 + tiny * tiny / 6, np.expm1(safe) / safe)
    phi2 = np.where(small, 0.5 + tiny / 6 + tiny * tiny / 24,
                    (np.expm1(safe) - safe) / (safe * safe))
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


def responses(
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
    u = as_signal(u, "u")
    ts = check_ts(ts)
    taus = tuple(float(t) for t in taus)
    if not taus or any(not (math.isfinite(t) and t > 0) for t in taus):
        raise ValueError(f"simulate_model: taus must be positive and finite, got {taus}")
    if not (math.isfinite(delay) and delay >= 0):
        raise ValueError(f"simulate_model: delay must be finite and >= 0, got {delay}")
    if hold not in HOLDS:
        raise ValueError(f"simulate_model: hold must be one of {HOLDS}, got {hold!r}")
    forced, free = responses(taus, delay, ts, hold, u)
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
    output = simulate_model(
        fit.gain,
        fit.taus,
        u,
        ts,
        delay=fit.delay,
        initial_state=x0,
        hold=fit.hold,  # type: ignore[arg-type]
    )
    return output + fit.offset


def as_signal(x: Any, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name}: non-finite value at index {int(bad[0])}")
    return arr


def check_ts(ts: Any) -> float:
    try:
        value = float(ts)
    except (TypeError, ValueError):
        raise ValueError(f"sample interval must be a number, got {ts!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"sample interval must be finite and > 0, got {value}")
    return value
