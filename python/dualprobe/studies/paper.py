"""Reproduction of the paper's section IV: identification (Tables I, II), studies A-C, hysteresis.

Every study is a function returning plain data (dicts / lists of floats);
:func:`dualprobe.studies.run.run_paper` runs them all, draws the figures
(:mod:`~dualprobe.studies.paper_figures`), writes a Markdown report that sets our numbers beside
the paper's (:mod:`~dualprobe.studies.paper_report`) and the JSON document of issue 3. The
tables, constants and settings are in :mod:`~dualprobe.studies.paper_setup`.

Choices where the paper is silent (documented in the report too):

* Identification "rig" (Tables I, II, hysteresis): the gas temperature steps from 20 to
  120 degC; the reference is a 50 um bare-wire thermocouple, modelled as a first-order lag of
  25 ms (the order of magnitude for such a wire at 15 m/s), sampled with the sensor at 100 Hz.
  The sensor output is the table's transfer function applied to that reference signal (so the
  table's model is exactly the one from reference to sensor). White noise 0.1 K on the
  reference, 0.05 K on the Pt-100. The step falls between samples.
* Simulation studies A-C (the paper's eq. 9 assumes a zero-order hold): noise-free, sample
  interval 0.1 s (10 Hz, well above the sensors' bandwidths), 200 s record, step 20 -> 120 degC
  at t = 10 s, on the sample grid so that the ZOH assumption of the estimator holds for the
  gas temperature itself. The estimator is the difference-equation method (paper eqs. 10-12)
  with GTLS for equal white noise on both sensors (only the ratio of the noise levels matters,
  so it is well defined on noise-free data), computed by the C++ core. The reconstruction is
  the exact inverse of sensor 1 (eq. 8 inverted, the paper's "Eq. (3)") with the estimated
  tau1. RMSEs are over the whole record against the gas temperature averaged over each sample
  interval (what a sampled reconstruction can recover; equal to the sampled gas temperature
  for a step on the grid). Time constants use the unit-gain models (the tables' gains are
  calibration, which the dual-sensor method assumes away).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from dualprobe import simulate as sim
from dualprobe.identify import TfFit, fit_transfer_function, simulate_fit
from dualprobe.studies.paper_setup import (
    PAPER_TABLES,
    PAPER_TAU_COOL,
    PAPER_TAU_HEAT,
    RIG,
    STUDY,
    STUDY_A_TAU1,
    STUDY_A_TAU2,
    STUDY_BC_TAU1,
    STUDY_BC_TAU2,
    DifferenceEngine,
    RigSettings,
    StudySettings,
    estimate_pair,
    finite_or_none,
    progress_bar,
    reconstruct_sensor1,
    study_record,
    sweep_values,
)

__all__ = [
    "hysteresis_study",
    "identification_record",
    "identify_tables",
    "reconstruction_trace",
    "study_a",
    "study_b",
    "study_c",
    "tables_monte_carlo",
]


def identification_record(
    sensor: sim.SensorModel,
    *,
    duration: float,
    rig: RigSettings = RIG,
    rng: np.random.Generator | int | None = None,
) -> dict[str, np.ndarray]:
    """Reference thermocouple (input) and sensor (output) for a gas step, with noise.

    The sensor sees the same gas as the reference; its model from the *reference* is
    ``sensor`` (the table's transfer function), so the sensor output is ``sensor`` applied to
    the continuous reference signal.
    """
    gen = np.random.default_rng(rng)
    t = rig.ts * np.arange(math.floor(duration / rig.ts + 1e-9) + 1)
    profile = sim.step_profile(rig.t_step, rig.low, rig.high)
    reference = sim.SensorModel((rig.reference_tau,))
    u_clean = sim.simulate_sensor(profile, reference, t)
    cascade = sim.SensorModel((*sensor.taus, rig.reference_tau), gain=sensor.gain)
    y_clean = sim.simulate_sensor(profile, cascade, t)
    u = u_clean + rig.reference_noise * gen.standard_normal(t.size)
    y = y_clean + rig.sensor_noise * gen.standard_normal(t.size)
    return {"t": t, "u": u, "y": y, "u_clean": u_clean, "y_clean": y_clean, "tg": profile(t)}


def _fit_summary(fit: TfFit) -> dict[str, Any]:
    return {
        "gain": fit.gain,
        "taus": list(fit.taus),
        "rmse": fit.rmse,
        "fit_percent": fit.fit_percent,
    }


def identify_tables(
    *, rig: RigSettings = RIG, seed: int = 0, with_records: bool = False
) -> dict[str, Any]:
    """Identify every table model from data generated with that model, plus the first-order
    fit of the second-order data (the comparison of the paper's Figs. 3 and 4).

    Returns ``{"tf_fits": {sensor: {"order1": {...}, "order2": {...}}}, "details": {...}}``
    where details hold the full fits (with uncertainties) and, with ``with_records``, the
    records and model outputs for the figures.
    """
    gen = np.random.default_rng(seed)
    tf_fits: dict[str, dict[str, Any]] = {}
    details: dict[str, Any] = {}
    records: dict[str, Any] = {}
    for name, models in PAPER_TABLES.items():
        duration = rig.duration(name)
        rec1 = identification_record(models["order1"], duration=duration, rig=rig, rng=gen)
        fit1 = fit_transfer_function(rec1["t"], rec1["u"], rec1["y"], order=1)
        rec2 = identification_record(models["order2"], duration=duration, rig=rig, rng=gen)
        fit2 = fit_transfer_function(rec2["t"], rec2["u"], rec2["y"], order=2)
        # Both orders fitted to the same (second-order) data: the paper's Figs. 3-4 claim.
        cross1 = fit_transfer_function(rec2["t"], rec2["u"], rec2["y"], order=1)
        tf_fits[name] = {"order1": _fit_summary(fit1), "order2": _fit_summary(fit2)}
        details[name] = {
            "order1": fit1.to_dict(),
            "order2": fit2.to_dict(),
            "order1_on_order2_data": cross1.to_dict(),
        }
        if with_records:
            records[name] = {
                "t": rec2["t"],
                "u": rec2["u"],
                "y": rec2["y"],
                "order1": simulate_fit(cross1, rec2["u"]),
                "order2": simulate_fit(fit2, rec2["u"]),
                "fit_order1": cross1,
                "fit_order2": fit2,
            }
    out: dict[str, Any] = {"tf_fits": tf_fits, "details": details}
    if with_records:
        out["records"] = records
    return out


def tables_monte_carlo(
    n_seeds: int, *, rig: RigSettings = RIG, first_seed: int = 1000, progress: bool = False
) -> dict[str, Any]:
    """Repeat the table identification over seeds: mean, spread and 1-sigma coverage."""
    per_param: dict[str, dict[str, list[tuple[float, float, float]]]] = {}
    seeds: Iterable[int] = range(first_seed, first_seed + n_seeds)
    if progress:
        from tqdm import tqdm

        seeds = tqdm(list(seeds), desc="tables Monte Carlo", unit="seed", leave=False)
    for seed in seeds:
        gen = np.random.default_rng(seed)
        for name, models in PAPER_TABLES.items():
            for order_key, model in models.items():
                order = 1 if order_key == "order1" else 2
                rec = identification_record(model, duration=rig.duration(name), rig=rig, rng=gen)
                fit = fit_transfer_function(rec["t"], rec["u"], rec["y"], order=order)
                truths = [("gain", model.gain)] + [
                    (f"tau{i + 1}", tau) for i, tau in enumerate(sorted(model.taus, reverse=True))
                ]
                estimates = [
                    (fit.gain, fit.gain_std),
                    *zip(fit.taus, fit.taus_std, strict=True),
                ]
                bucket = per_param.setdefault(f"{name}/{order_key}", {})
                for (pname, truth), (value, std) in zip(truths, estimates, strict=True):
                    bucket.setdefault(pname, []).append((value, std, truth))
    summary: dict[str, Any] = {"n_seeds": n_seeds, "models": {}}
    for key, params in per_param.items():
        summary["models"][key] = {}
        for pname, rows in params.items():
            arr = np.array(rows)
            values, stds, truth = arr[:, 0], arr[:, 1], arr[0, 2]
            summary["models"][key][pname] = {
                "truth": float(truth),
                "mean": float(np.mean(values)),
                "std": float(np.std(values, ddof=1)) if len(values) > 1 else 0.0,
                "mean_reported_std": float(np.mean(stds)),
                "coverage_1sigma": float(np.mean(np.abs(values - truth) <= stds)),
            }
    return summary


def _rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    valid = np.isfinite(estimate[:-1])
    if not np.any(valid):
        return math.nan
    diff = estimate[:-1][valid] - truth[:-1][valid]
    return float(np.sqrt(np.mean(diff * diff)))


def _prefiltered_interval_mean(
    recording: sim.PairRecording, tau: float, settings: StudySettings
) -> np.ndarray:
    """Mean over [t_k, t_k+1] of the gas temperature filtered by 1/(1 + tau s).

    From tau x' = Tg - x: int x = int Tg - tau (x(t_k+1) - x(t_k)), and Tg is constant over
    each sample interval (step on the grid), so its interval mean is the sample tg[k].
    """
    filtered = sim.simulate_sensor(settings.profile(), sim.SensorModel((tau,)), recording.t)
    out = np.full(recording.t.size, np.nan)
    out[:-1] = recording.tg[:-1] - tau / settings.ts * np.diff(filtered)
    return out


def _study_point(
    sensor1: sim.SensorModel,
    sensor2: sim.SensorModel,
    settings: StudySettings,
    estimator: str | DifferenceEngine,
    prefilter_tau: float | None,
) -> dict[str, Any]:
    rec = study_record(sensor1, sensor2, settings)
    est = estimate_pair(rec.t1, rec.t2, settings.ts, method=settings.method, estimator=estimator)
    point: dict[str, Any] = {"tau1": None, "tau2": None, "rmse": None}
    if est["status"] == "ok":
        recon = reconstruct_sensor1(rec.t1, est["tau1"], settings.ts, estimator=estimator)
        point = {
            "tau1": float(est["tau1"]),
            "tau2": float(est["tau2"]),
            "rmse": finite_or_none(_rmse(recon, rec.tg)),
        }
        if prefilter_tau is not None:
            reference = _prefiltered_interval_mean(rec, prefilter_tau, settings)
            point["rmse_prefiltered"] = finite_or_none(_rmse(recon, reference))
    elif prefilter_tau is not None:
        point["rmse_prefiltered"] = None
    point["status"] = est["status"]
    return point


def study_a(
    a_p_values: Sequence[float] | None = None,
    *,
    settings: StudySettings = STUDY,
    estimator: str | DifferenceEngine = "core",
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Study A (Figs. 5-9): sensor 1 = 1/(1 + 12.48 s), sensor 2 = 1/((1 + a_p s)(1 + 28.95 s)).

    Returns one dict per a_p: a_p, tau1, tau2 (estimated), rmse (reconstruction from sensor 1
    against the gas temperature), status.
    """
    values = sweep_values(False) if a_p_values is None else list(a_p_values)
    out = []
    for a_p in progress_bar(values, "study A", progress):
        s1 = sim.SensorModel((STUDY_A_TAU1,))
        s2 = sim.SensorModel((STUDY_A_TAU2, a_p))
        out.append({"a_p": float(a_p), **_study_point(s1, s2, settings, estimator, None)})
    return out


def study_b(
    a_p_values: Sequence[float] | None = None,
    *,
    settings: StudySettings = STUDY,
    estimator: str | DifferenceEngine = "core",
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Study B (Figs. 10-11): sensor 1 = Table I second order, sensor 2 = 1/((1 + a_p s)
    (1 + 25.72 s)). Also rmse_prefiltered: against the gas temperature filtered by sensor 1's
    fast pole (0.17 s), which is what the reconstruction can at best return."""
    values = sweep_values(False) if a_p_values is None else list(a_p_values)
    out = []
    for a_p in progress_bar(values, "study B", progress):
        s1 = sim.SensorModel(STUDY_BC_TAU1)
        s2 = sim.SensorModel((STUDY_BC_TAU2, a_p))
        point = _study_point(s1, s2, settings, estimator, STUDY_BC_TAU1[1])
        out.append({"a_p": float(a_p), **point})
    return out


def study_c(
    a_p_values: Sequence[float] | None = None,
    *,
    settings: StudySettings = STUDY,
    estimator: str | DifferenceEngine = "core",
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Study C (Figs. 12-14): both second order with an equal fast pole a_p: sensor 1 =
    1/((1 + a_p s)(1 + 12.30 s)), sensor 2 = 1/((1 + a_p s)(1 + 25.72 s)). rmse against the
    gas temperature, rmse_prefiltered against it pre-filtered by 1/(1 + a_p s) (eqs. 13-16)."""
    values = sweep_values(False) if a_p_values is None else list(a_p_values)
    out = []
    for a_p in progress_bar(values, "study C", progress):
        s1 = sim.SensorModel((STUDY_BC_TAU1[0], a_p))
        s2 = sim.SensorModel((STUDY_BC_TAU2, a_p))
        out.append({"a_p": float(a_p), **_study_point(s1, s2, settings, estimator, a_p)})
    return out


def reconstruction_trace(
    a_p: float, *, settings: StudySettings = STUDY, estimator: str | DifferenceEngine = "core"
) -> dict[str, Any]:
    """Study A record and reconstruction at one a_p (Figs. 8, 9)."""
    rec = study_record(
        sim.SensorModel((STUDY_A_TAU1,)), sim.SensorModel((STUDY_A_TAU2, a_p)), settings
    )
    est = estimate_pair(rec.t1, rec.t2, settings.ts, method=settings.method, estimator=estimator)
    recon = (
        reconstruct_sensor1(rec.t1, est["tau1"], settings.ts, estimator=estimator)
        if est["status"] == "ok"
        else np.full(rec.t.size, np.nan)
    )
    return {"t": rec.t, "tg": rec.tg, "t1": rec.t1, "t2": rec.t2, "tgr": recon, "estimate": est}


def hysteresis_study(
    *,
    rig: RigSettings = RIG,
    tau_heat: float = PAPER_TAU_HEAT,
    tau_cool: float = PAPER_TAU_COOL,
    seed: int = 0,
    with_records: bool = False,
) -> dict[str, Any]:
    """A heating step then a cooling step of a first-order sensor whose time constant depends
    on the direction of heat flow; a first-order model is identified (reference -> sensor) on
    each step separately.

    Returns tau_heat, tau_cool (estimated), their 1-sigma values and the fitted gains.
    """
    gen = np.random.default_rng(seed)
    hold = rig.hysteresis_hold
    duration = 2.0 * hold
    t = rig.ts * np.arange(math.floor(duration / rig.ts + 1e-9) + 1)
    t_down = rig.t_step + hold
    profile = sim.step_profile(rig.t_step, rig.low, rig.high) + sim.step_profile(
        t_down, 0.0, rig.low - rig.high
    )
    u = sim.simulate_sensor(profile, sim.SensorModel((rig.reference_tau,)), t)
    y = sim.simulate_hysteretic_sensor(profile, tau_heat, tau_cool, t)
    u = u + rig.reference_noise * gen.standard_normal(t.size)
    y = y + rig.sensor_noise * gen.standard_normal(t.size)
    # Split half-way between the steps' ends: each part holds exactly one step.
    split = int(np.searchsorted(t, t_down - 0.5 * rig.t_step))
    heat = fit_transfer_function(rig.ts, u[:split], y[:split], order=1)
    cool = fit_transfer_function(rig.ts, u[split:], y[split:], order=1)
    out: dict[str, Any] = {
        "tau_heat": heat.taus[0],
        "tau_cool": cool.taus[0],
        "tau_heat_std": heat.taus_std[0],
        "tau_cool_std": cool.taus_std[0],
        "gain_heat": heat.gain,
        "gain_cool": cool.gain,
        "fit_percent_heat": heat.fit_percent,
        "fit_percent_cool": cool.fit_percent,
        "true_tau_heat": float(tau_heat),
        "true_tau_cool": float(tau_cool),
    }
    if with_records:
        out["records"] = {
            "heating": {"t": t[:split], "u": u[:split], "y": y[:split], "fit": heat},
            "cooling": {"t": t[split:], "u": u[split:], "y": y[split:], "fit": cool},
        }
    return out
