"""Pt-100 resistance and temperature (IEC 60751 Callendar-Van Dusen).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "pt100_resistance",
    "pt100_temperature",
]


_R0 = 100.0
_A = 3.9083e-3
_B = -5.775e-7
_C = -4.183e-12
_T_MIN, _T_MAX = -200.0, 850.0  # IEC 60751 validity range (degC)


def pt100_resistance(temp_c: np.ndarray | float) -> np.ndarray | float:
    """Pt-100 resistance (ohm) at ``temp_c`` (degC), IEC 60751, valid -200..850 degC."""
    temp = np.asarray(temp_c, dtype=float)
    if not np.all(np.isfinite(temp)) or np.any((temp < _T_MIN) | (temp > _T_MAX)):
        raise ValueError(f"pt100_resistance: temperature outside {_T_MIN}..{_T_MAX} degC")
    cubic = np.where(temp < 0.0, _C * (temp - 100.0) * temp**3, 0.0)
    r = _R0 * (1.0 + _A * temp + _B * temp**2 + cubic)
    return float(r) if r.ndim == 0 else r


def pt100_temperature(resistance_ohm: np.ndarray | float) -> np.ndarray | float:
    """Inverse of :func:`pt100_resistance`: closed form at and above 0 degC, Newton below."""
    r = np.asarray(resistance_ohm, dtype=float) / _R0
    lo, hi = (pt100_resistance(_T_MIN) / _R0, pt100_resistance(_T_MAX) / _R0)
    if not np.all(np.isfinite(r)) or np.any((r < lo * (1 - 1e-12)) | (r > hi * (1 + 1e-12))):
        raise ValueError(
            f"pt100_temperature: resistance outside {lo * _R0:.4f}..{hi * _R0:.4f} ohm"
        )
    # Quadratic root in the cancellation-free form 2(r-1) / (A + sqrt(A^2 + 4B(r-1)))
    temp = 2.0 * (r - 1.0) / (_A + np.sqrt(_A**2 + 4.0 * _B * (r - 1.0)))
    below = r < 1.0
    if np.any(below):
        tb = temp[below]
        rb = r[below]
        for _ in range(50):  # quadratic start is within ~0.1 K: converges in 2-3 steps
            f = 1.0 + _A * tb + _B * tb**2 + _C * (tb - 100.0) * tb**3 - rb
            df = _A + 2.0 * _B * tb + _C * (4.0 * tb**3 - 300.0 * tb**2)
            step = f / df
            tb = tb - step
            if np.all(np.abs(step) <= 1e-13 * (1.0 + np.abs(tb))):
                break
        temp = temp.copy()
        temp[below] = tb
    return float(temp) if temp.ndim == 0 else temp
