"""The noise-robust default of ``characterise_pair``: ``method="auto" | "svf"``.

It runs the state-variable-filter (SVF) cross-relation estimator (design.md 1.4; the
computations in :mod:`dualprobe.estimation.svf_backend`, the maths and measurements in the
docstring of :mod:`dualprobe.reference.svf`) with

* the noise level of each sensor estimated from its own signal
  (:func:`dualprobe.models.noise.estimate_noise_std`) unless given, and floored at 1e-6 of the
  signal's standard deviation and at the first-order-hold error of the signal's kinks
  (:func:`discretisation_noise_std`; exact data);
* the filter time constant ``tf`` chosen from the data: a geometric scan of tf over the
  record's time scales (first-order fits), then the fixed point ``tf = kappa tau_fast(tf)``
  (kappa = 0.5 for order 1 and the hysteresis split, 0.25 for order 2);
* the static model: unit gains (design.md) unless the affine model (gain ratio and offset
  between the sensors) lowers the smallest generalised eigenvalue by more than
  ``GAP_THRESHOLD`` noise standard deviations;
* an identifiability check from the generalised eigenvalues mu_1 <= mu_2 <= ...: with the
  right noise model the noise-only eigenvalues sit at 1 and scatter by sqrt(2/N_eff)
  (N_eff: effective independent rows). k eigenvalues within ``GAP_THRESHOLD`` of that
  band form a k-dimensional near-null space, i.e. a factor of degree k-1 common to both
  sensors (P1 = Q R1, P2 = Q R2 makes ``(1 + gamma s) R1 T1 = (1 + gamma s) R2 T2`` hold for
  every gamma). A common pole filters the gas temperature before both sensors and cannot be
  seen, so the reduced-order fit (the distinct poles R1, R2) is reported with
  ``identifiability["identifiable"] = False`` and a message; k-1 >= order means nothing is
  identifiable (identical sensors or no excitation);
* for order 2, the order of each sensor: a sensor whose second time constant is ~0 (truly
  first order, or far below what the sample rate and noise resolve) is fitted as first order
  when that fits as well by the same test (``identifiability["sensor_orders"]`` and
  ``["notes"]``). Otherwise its free d_i absorbs noise and discretisation error, and a first-
  order sensor even admits a near-null common factor that put a spurious 0.05 s pole on both
  sensors in the paper's noise-free study A (Ts = 0.1 s); with the selection, study A gives
  sensor 1 = 12.4797-12.4800 s alone and sensor 2's a_p to 4 % at 0.001 s, 0.1 % from 0.1 s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.ndimage

from dualprobe.estimation.result import PairEstimate
from dualprobe.estimation.svf_backend import (
    SvfResult,
    effective_samples,
    estimate_or_none,
    fast_time_constant,
    sensor_order_fits,
)

__all__ = [
    "DIRECTION_TOLERANCE",
    "GAP_THRESHOLD",
    "KAPPA",
    "RESOLUTION_FLOOR",
    "characterise_svf",
    "choose_filter_time_constant",
    "discretisation_noise_std",
]


# An eigenvalue counts as "noise only" when its excess over the noise band is below this many
# standard deviations of the noise-only spread: exact common factors gave 0-2.5 (25 simulated
# records, 10-100 Hz, 0.01-0.1 K); distinct poles 0.17 s / 0.19 s at 100 Hz, 0.01 K gave
# >= 160 (and were estimated to 2 %).
GAP_THRESHOLD = 10.0
KAPPA = {1: 0.5, 2: 0.25}  # tf / tau_fast, see dualprobe.reference.svf
RESOLUTION_FLOOR = 1e-6  # noise std used at least this fraction of the signal's std
DIRECTION_TOLERANCE = 0.01  # slope noise / RMS slope for the heating/cooling classification


_KINK_MEDIAN_WINDOW = 11  # running median of the second differences: kinks are 2 samples wide
_KINK_THRESHOLD = 8.0  # kink spikes: beyond 8 noise standard deviations of a second difference


def discretisation_noise_std(x: np.ndarray, noise_std: float = 0.0) -> float:
    """White noise equivalent to the first-order-hold error at the kinks of a sampled signal.

    The SVF sees the straight-line interpolation of the samples. On smooth stretches its error
    acts as the common operator ``1 - (Ts s)^2/12`` on both sensors and cancels from the
    cross-relation; at a kink (slope jump D, a gas step seen by a first-order sensor) it leaves
    an impulse of area up to ``Ts^2 D / 12``. The kink shows as a spike of about ``Ts D`` in the
    second differences above their running median (``r``), so the impulses' energy ``sum A^2``
    equals that of white noise of variance ``sum r^2 / (144 N)`` over the N samples. Only
    spikes above 8 noise standard deviations count (below, the noise hides them). Measured on
    the paper's noise-free study A (Ts = 0.1 s, 100 K step on the grid): 1.5e-3 K for the
    first-order sensor, where the fits' residuals then sit at 0.001-0.6 of this noise band.
    """
    d = np.diff(np.asarray(x, dtype=float), 2)
    if d.size < _KINK_MEDIAN_WINDOW:
        return 0.0
    spikes = d - scipy.ndimage.median_filter(d, size=_KINK_MEDIAN_WINDOW, mode="nearest")
    spikes = spikes[np.abs(spikes) > _KINK_THRESHOLD * math.sqrt(6.0) * noise_std]
    return math.sqrt(float(np.sum(spikes * spikes)) / (144.0 * (d.size + 2)))


def choose_filter_time_constant(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    order: int,
    sigma: tuple[float, float],
    static: str = "affine",
) -> tuple[float, list[float]]:
    """Filter time constant from the data: ``tf = kappa * tau_fast`` at its fixed point.

    A geometric scan (factor 4) from 2 Ts to a tenth of the record gives first-order fits
    (``static`` model; affine by default so that a gain mismatch cannot mislead the scan);
    the scan point closest to its own fixed point starts up to four refinement steps.
    Returns (tf, the tf values visited after the scan).
    """
    kappa = KAPPA[order]
    duration = (t1.size - 1) * ts
    tf_min = ts
    tf_max = max(tf_min, duration / 10.0)
    grid = [2.0 * ts * 4.0**j for j in range(64) if 2.0 * ts * 4.0**j <= tf_max] or [tf_max]

    def fast_at(tf: float) -> float:
        res = estimate_or_none(t1, t2, ts, tf=tf, order=1, sigma1=sigma[0], sigma2=sigma[1],
                             static=static, diagnostics=False)
        return fast_time_constant(res)

    best: tuple[float, float] | None = None  # (log mismatch, tf)
    for tf in grid:
        fast = fast_at(tf)
        if math.isfinite(fast):
            mismatch = abs(math.log(tf / (kappa * fast)))
            if best is None or mismatch < best[0]:
                best = (mismatch, tf)
    if best is None:
        return grid[len(grid) // 2], []
    tf = best[1]
    history = [tf]
    for _ in range(4):
        fast = fast_at(tf)
        if not math.isfinite(fast):
            break
        new = min(max(kappa * fast, tf_min), tf_max)
        history.append(new)
        converged = abs(new / tf - 1.0) < 0.05
        tf = new
        if converged:
            break
    return tf, history


def _gap_statistics(mu: np.ndarray, n_eff: float) -> np.ndarray:
    """Excess of each generalised eigenvalue over the noise band, in noise standard deviations.

    The band sits at mu = 1 when the noise model is right; a larger smallest eigenvalue
    (model error) raises it, a smaller one (noise overestimated, e.g. the resolution floor
    on exact data) does not lower it.
    """
    mu = np.asarray(mu, dtype=float)
    reference = max(float(mu[0]), 1.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        gaps = (mu / reference - 1.0) * math.sqrt(n_eff / 2.0)
    gaps = np.where(np.isfinite(gaps), gaps, np.inf)
    gaps[0] = 0.0
    return gaps


def _resolved(taus: tuple[float, ...], poly: tuple[float, ...]) -> tuple[tuple[float, ...], str]:
    """Time constants of one sensor's polynomial, with a note when only part is resolved."""
    if all(math.isfinite(t) and t > 0.0 for t in taus):
        return taus, ""
    c = poly[0]
    if len(poly) == 2 and math.isfinite(c) and c > 0.0:
        d = poly[1]
        if d <= 0.0:
            return (c,), "second time constant below resolution (first-order response)"
        if c * c < 4.0 * d:
            return (0.5 * c, 0.5 * c), "complex pole pair: reported as a double pole"
    return taus, "no positive real time constants"


def _beta(taus: tuple[tuple[float, ...], tuple[float, ...]], ts: float) -> float | None:
    if len(taus[0]) != 1 or len(taus[1]) != 1:
        return None
    b1 = -math.expm1(-ts / taus[0][0])
    b2 = -math.expm1(-ts / taus[1][0])
    return b2 / b1


@dataclass
class _SvfRun:
    """One SVF characterisation: the data, the settings and the growing details."""

    t1: np.ndarray
    t2: np.ndarray
    ts: float
    order: int
    hysteresis: bool
    sigma: tuple[float, float]
    static: str
    details: dict[str, object]
    tf: float = float("nan")

    def fit(self, order: int, static: str, hysteresis: bool) -> SvfResult | None:
        kwargs: dict[str, Any] = {"tf": self.tf, "order": order, "sigma1": self.sigma[0],
                                  "sigma2": self.sigma[1], "static": static}
        if hysteresis:
            kwargs.update(hysteresis=True, direction_tolerance=DIRECTION_TOLERANCE)
        return estimate_or_none(self.t1, self.t2, self.ts, **kwargs)

    def failed(self, status: str, message: str,
               identifiability: dict[str, object] | None = None) -> PairEstimate:
        self.details["message"] = message
        return PairEstimate(
            status=status, method="svf", order=self.order, sample_interval=self.ts,
            time_constants=(tuple(float("nan") for _ in range(self.order)),) * 2, beta=None,
            noise_std=self.sigma, identifiability=identifiability or {}, details=self.details,
        )

    def run(self, tf: float | None) -> PairEstimate:
        if tf is None:
            scan_static = "unit" if self.static == "unit" else "affine"
            tf, history = choose_filter_time_constant(
                self.t1, self.t2, self.ts, self.order, self.sigma, scan_static)
            self.details["filter_time_constant_history"] = history
            self.details["filter_time_constant_source"] = "auto"
        else:
            self.details["filter_time_constant_source"] = "given"
        self.tf = tf
        self.details["filter_time_constant"] = tf
        res, static = self.select_static()
        if res is None:
            need = "a heating and a cooling episode of each sensor" if self.hysteresis else \
                "temperature changes"
            return self.failed("insufficient_excitation",
                               f"the signals do not excite the model (need {need})")
        n_eff = effective_samples(res, self.ts, self.sigma, static)
        gaps = _gap_statistics(res.eigenvalues, n_eff)
        k = int(np.count_nonzero(gaps < GAP_THRESHOLD))
        mu = np.asarray(res.eigenvalues, dtype=float)
        self.details.update(
            static_model=static, rows=res.rows, theta=res.theta.tolist(),
            eigenvalues=mu.tolist(), effective_samples=n_eff, gap_statistics=gaps.tolist(),
            residual_to_noise=float(mu[0]),
        )
        if static == "affine":
            self.details.update(gain_ratio=res.extra["gain_ratio"], offset=res.extra["offset"])
        if self.hysteresis:
            self.details["direction_half_windows"] = list(
                res.extra["direction_half_windows"])  # type: ignore[call-overload]
        identifiability: dict[str, object] = {
            "identifiable": k == 1,
            "null_dimension": k,
            "eigenvalue_ratio": float(mu[1] / mu[0]) if mu[0] > 0.0 else float("inf"),
            "gap_statistic": float(gaps[1]),
        }
        misfit = (float(mu[0]) - 1.0) * math.sqrt(n_eff / 2.0)
        if misfit > GAP_THRESHOLD:
            identifiability["model_misfit"] = (
                f"the model leaves {float(mu[0]):.3g} times the residual that sensor noise "
                "explains: the sensors may be of higher order, hysteretic, nonlinear or see "
                "different gas temperatures")
        if self.order == 2 and not self.hysteresis and k <= 2:
            chosen = self.select_sensor_orders(res, static, n_eff, identifiability)
            if chosen is not None:
                return self.finish(chosen, chosen.order, identifiability)
        if k > 1:
            return self.reduced(res, static, k, identifiability)
        return self.finish(res, self.order, identifiability)

    def select_sensor_orders(self, res: SvfResult, static: str, n_eff: float,
                             identifiability: dict[str, object]) -> SvfResult | None:
        """Drop a sensor's second-order coefficient d_i when the data do not need it.

        A sensor whose second time constant is ~0 (a first-order sensor, or one far below
        what the sample rate and the noise resolve) leaves d_i ~ 0 in the relation. The free
        coefficient then absorbs noise and discretisation error: negative, complex or spurious
        small poles. If the sensor is exactly first order, ``(1 + g s) P1 T1 = (1 + g s) P2 T2``
        even fits for any g up to P2's tiny s^3 term, a near-null direction that adds a
        spurious common pole g to both sensors' fast poles (paper's study A, noise-free,
        a_p = 0.001 s: 0.051 s on both instead of 0 and 0.001 s). Sub-models without d1, d2 or
        both are solved on the same scatter; one is kept when its smallest generalised
        eigenvalue exceeds the full model's by less than ``GAP_THRESHOLD`` noise standard
        deviations (the test of the identifiability check), the least costly first.

        Returns the chosen fit, or None when the full model is degenerate (two-dimensional
        null space) and no sub-model with one first-order sensor removes the degeneracy:
        then a first-order pair fits as well, i.e. both sensors are first order or share a
        pole, which :meth:`reduced` reports.
        """
        degenerate = int(identifiability["null_dimension"]) > 1  # type: ignore[call-overload]
        try:
            fits = sensor_order_fits(self.t1, self.t2, self.ts, self.tf, self.sigma, static)
        except (np.linalg.LinAlgError, ValueError):  # as estimate_or_none: no usable scatter
            return None if degenerate else res
        full = fits[(2, 2)]
        reference = max(full.mu, 1.0)
        statistics = {key: (fit.mu - full.mu) / reference * math.sqrt(n_eff / 2.0)
                      for key, fit in fits.items()}
        self.details["sensor_order_statistics"] = {
            f"{key[0]},{key[1]}": statistics[key] for key in fits if key != (2, 2)}
        if degenerate and statistics[(1, 1)] < GAP_THRESHOLD:
            return None
        chosen = (2, 2)
        for key in sorted(((1, 2), (2, 1)), key=lambda key: statistics[key]):
            if not (statistics[key] < GAP_THRESHOLD and fits[key].feasible):
                continue
            if degenerate and _gap_statistics(fits[key].eigenvalues, n_eff)[1] < GAP_THRESHOLD:
                continue  # the sub-model is degenerate too
            chosen = key
            break
        if degenerate and chosen == (2, 2):
            return None
        if chosen != (2, 2) and statistics[(1, 1)] < GAP_THRESHOLD and fits[(1, 1)].feasible:
            chosen = (1, 1)
        identifiability["sensor_orders"] = list(chosen)
        if chosen == (2, 2):
            return res
        if degenerate:
            identifiability.update(identifiable=True, null_dimension=1,
                                   full_model_null_dimension=2)
        notes = []
        for i, key in enumerate(((1, 2), (2, 1))):
            if chosen[i] == 1:
                statistic = statistics[(1, 1) if chosen == (1, 1) else key]
                notes.append(
                    f"sensor {i + 1}: second time constant not resolved (a first-order model "
                    f"of this sensor fits as well: statistic {statistic:.3g} < "
                    f"{GAP_THRESHOLD:g}); reported as first order")
        if chosen in ((1, 2), (2, 1)):
            other = 2 if chosen == (1, 2) else 1
            notes.append(
                f"a fast pole common to both sensors would not be seen: if sensor {3 - other} "
                f"has one too, sensor {other}'s reported fast time constant is the difference")
        identifiability["notes"] = notes
        fit = fits[chosen]
        self.details.update(theta=fit.theta.tolist(), eigenvalues=fit.eigenvalues.tolist(),
                            residual_to_noise=float(fit.mu))
        return dataclasses.replace(
            res, order=max(chosen), theta=fit.theta, time_constants=fit.time_constants,
            polynomials=fit.polynomials, eigenvalues=fit.eigenvalues,
        )

    def select_static(self) -> tuple[SvfResult | None, str]:
        """Fit the unit-gain model and, for "auto", the affine one; keep the affine model only
        when it explains significantly more (gain or offset mismatch between the sensors)."""
        if self.static != "auto":
            return self.fit(self.order, self.static, self.hysteresis), self.static
        unit = self.fit(self.order, "unit", self.hysteresis)
        affine = self.fit(self.order, "affine", self.hysteresis)
        if affine is None:
            return unit, "unit"
        if unit is None:
            return affine, "affine"
        n_eff = effective_samples(unit, self.ts, self.sigma, "unit")
        gain = (float(unit.eigenvalues[0]) / max(float(affine.eigenvalues[0]), 1.0) - 1.0)
        statistic = gain * math.sqrt(n_eff / 2.0)
        self.details["static_model_statistic"] = statistic
        return (affine, "affine") if statistic > GAP_THRESHOLD else (unit, "unit")

    def finish(self, res: SvfResult, order: int,
               identifiability: dict[str, object]) -> PairEstimate:
        if "heat" in res.extra:
            heat = res.extra["heat"]
            cool = res.extra["cool"]
            values = [heat[0][0], cool[0][0], heat[1][0], cool[1][0]]  # type: ignore[index]
            if res.status != "ok" or not all(math.isfinite(v) and v > 0.0 for v in values):
                return self.failed("infeasible", "no positive heating/cooling time constants "
                                   "fit these signals", identifiability)
            return PairEstimate(
                status="ok", method="svf", order=1, sample_interval=self.ts,
                time_constants=res.time_constants, beta=_beta(res.time_constants, self.ts),
                noise_std=self.sigma, time_constants_heat=heat,  # type: ignore[arg-type]
                time_constants_cool=cool,  # type: ignore[arg-type]
                identifiability=identifiability, details=self.details,
            )
        notes = []
        taus = []
        for i in range(2):
            t, note = _resolved(res.time_constants[i], res.polynomials[i])
            if note == "no positive real time constants":
                return self.failed("infeasible", f"sensor {i + 1}: {note} fit these signals "
                                   "(check the columns)", identifiability)
            if note:
                notes.append(f"sensor {i + 1}: {note}")
            taus.append(t)
        if notes:
            identifiability["notes"] = notes
        tcs = (tuple(taus[0]), tuple(taus[1]))
        return PairEstimate(
            status="ok", method="svf", order=order, sample_interval=self.ts,
            time_constants=tcs, beta=_beta(tcs, self.ts), noise_std=self.sigma,
            identifiability=identifiability, details=self.details,
        )

    def reduced(self, res: SvfResult, static: str, k: int,
                identifiability: dict[str, object]) -> PairEstimate:
        """k-dimensional near-null space: report what the data do determine."""
        if self.hysteresis:
            message = ("heating and cooling time constants are not separately identifiable "
                       "from these signals (too few or too weak heating/cooling episodes); the "
                       "common time constants are reported")
            identifiability["message"] = message
            common = self.fit(1, static, False)
            if common is None or common.status != "ok":
                return self.failed("insufficient_excitation", message, identifiability)
            return self.finish(common, 1, identifiability)
        reduced_order = self.order - (k - 1)
        if reduced_order < 1:
            message = ("the time constants are not identifiable: within the noise the two "
                       "signals are explained by identical sensors or by no excitation (record "
                       "larger temperature changes; check that the two sensors differ)")
            identifiability["message"] = message
            return self.failed("insufficient_excitation", message, identifiability)
        low = self.fit(reduced_order, static, False)
        if low is None or low.status != "ok":
            message = "the time constants are not identifiable from these signals"
            identifiability["message"] = message
            return self.failed("insufficient_excitation", message, identifiability)
        shared = "a pole" if k == 2 else f"{k - 1} poles"
        identifiability.update(
            shared_pole=None,
            shared_poles=k - 1,
            distinct_time_constants=[list(low.time_constants[0]), list(low.time_constants[1])],
            message=(
                f"the two sensors (nearly) share {shared} (gap statistic "
                f"{float(identifiability['gap_statistic']):.3g} < {GAP_THRESHOLD:g}), or "
                f"are both of order {reduced_order} within the noise: a pole common to both "
                "acts like a filter on the gas temperature and cannot be seen from the two "
                "signals; only the distinct time constants are identifiable and reported "
                f"(order {reduced_order})"
            ),
        )
        self.details["requested_order"] = self.order
        return self.finish(low, reduced_order, identifiability)


def characterise_svf(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    order: int,
    hysteresis: bool,
    sigma: tuple[float, float],
    sigma_source: str,
    tf: float | None,
    static: str,
) -> PairEstimate:
    """The SVF characterisation (module docstring) of checked signals with the noise levels
    ``sigma`` (given or estimated: ``sigma_source``); ``tf`` None chooses the filter time
    constant, ``static`` is auto | unit | affine."""
    details: dict[str, object] = {"noise_std_source": sigma_source}
    # Resolution floor: nothing below a part per million of a signal's variation is resolved
    # (rounding errors of exact data sit there), nor below the discretisation error at the
    # signals' kinks, so noise-free records keep a meaningful noise band for the
    # identifiability test and the order selection.
    floor = tuple(
        max(RESOLUTION_FLOOR * float(np.std(x)), discretisation_noise_std(x, s))
        for x, s in ((t1, sigma[0]), (t2, sigma[1]))
    )
    used = (max(sigma[0], floor[0]), max(sigma[1], floor[1]))
    if used != sigma:
        details["noise_std_used"] = used
    result = _SvfRun(t1, t2, ts, order, hysteresis, used, static, details).run(tf)
    return dataclasses.replace(result, noise_std=sigma)
