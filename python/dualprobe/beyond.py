"""Beyond the paper: second-order and hysteresis-aware dual-sensor characterisation (issue 6).

The paper concludes (section V) that a first-order model cannot characterise a dual-RTD probe
and that a higher-order model "will require additional sensors". Two sensors are enough: with
the gas temperature eliminated they satisfy ``P1(s) T1 = P2(s) T2``, which the cross-relation
(SVF) estimator of :mod:`dualprobe.estimation` solves for second-order P_i as well. This module
reruns the paper's studies with it and writes the "Beyond the paper" section of
``dualprobe paper`` (:func:`run_beyond`):

* Studies A and B (:func:`compare_study`) on the paper's own data (noise-free, 10 Hz, 100 K
  step on the sample grid, :data:`dualprobe.paper.STUDY`) and on the same data with 0.01 K of
  white noise on each sensor. On every record three methods: the paper's (difference-equation
  GTLS, exact first-order inverse of sensor 1; :func:`dualprobe.paper.estimate_pair`), and
  ``characterise_pair`` of order 1 and of order 2, each followed by a reconstruction from both
  sensors. Noise-free: the exact zero-order-hold inverse of each identified sensor
  (:func:`zoh_inverse`: the paper's eq. 8 inverse, generalised to second order; the studies'
  gas is piecewise constant on the grid, so it is exact for the true model), weighted by
  inverse noise gain. With noise: ``reconstruct_pair`` in the product's default mode (the
  smoother), with the identified time constants (both per sensor for order 2).
* The issue's 100 Hz pair (:func:`second_order_pair`): Tables I/II second-order models (unit
  gain), 0.01 K, 100-300 K steps off the grid; order 1 vs order 2, reconstruction by
  ``reconstruct_pair`` (default mode, smoother).
* A hysteretic pair (:func:`hysteretic_pair`): both sensors heat faster than they cool (the
  paper's 21.96 s / 28.86 s; the slower sensor scaled by Table II/Table I = 28.95/12.48),
  10 Hz, 0.05 K; hysteresis-aware identification vs the plain first-order one, and the
  reconstructions with heating/cooling time constants vs common ones.
* The identifiability diagnostic (:func:`identifiability_cases`) on study C's equal poles and
  on the pairs above.

RMSEs are against the gas temperature at the sample instants, over the samples whose both
reconstructions are finite, leaving out the samples right beside a gas jump (where a sampled
reconstruction cannot tell the levels apart; ``PairRecording.jump_mask``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe import paper
from dualprobe import simulate as sim
from dualprobe.estimation import PairEstimate, characterise_pair
from dualprobe.reconstruction import zoh_inverse

__all__ = [
    "NOISE_STD",
    "compare_study",
    "hysteretic_pair",
    "identifiability_cases",
    "near_equal_band",
    "run_beyond",
    "second_order_pair",
    "sweeps",
    "worst_ratio",
    "zoh_inverse",
    "zoh_inverse_pair",
]

NOISE_STD = 0.01  # K, white noise of the "with noise" variant (a good Pt-100 channel)
STUDIES = ("A", "B")
# Hysteresis (paper, Figs. 15-16) for the faster sensor; the slower one scaled by Table II /
# Table I first-order time constants.
HYSTERESIS_HEAT = (sim.PT100_1P5MM_TAU_HEAT, sim.PT100_1P5MM_TAU_HEAT * 28.95 / 12.48)
HYSTERESIS_COOL = (sim.PT100_1P5MM_TAU_COOL, sim.PT100_1P5MM_TAU_COOL * 28.95 / 12.48)
SECOND_ORDER_MODELS = (sim.SensorModel((12.30, 0.17)), sim.SensorModel((25.72, 1.08)))
_INVERSE_GAIN_SAMPLES = 4096  # impulse-response length for the inverse weights (ample)


# --------------------------------------------------------------------------------------------
# Exact zero-order-hold inverse of a (first- or second-order) sensor
# --------------------------------------------------------------------------------------------


def _inverse_noise_gain(taus: Sequence[float], ts: float) -> float:
    """Squared noise gain of :func:`zoh_inverse`: the sum of its squared impulse response
    (truncated where a slow sampling zero would make it longer than the cap)."""
    impulse = np.zeros(_INVERSE_GAIN_SAMPLES)
    impulse[1] = 1.0
    response = zoh_inverse(impulse, taus, ts)[:-1]
    return float(np.sum(response * response))


def zoh_inverse_pair(
    t1: np.ndarray, t2: np.ndarray, ts: float, taus1: Sequence[float], taus2: Sequence[float]
) -> np.ndarray:
    """Both sensors' :func:`zoh_inverse` combined with inverse-noise-gain weights (equal white
    noise on both sensors; design.md 1.3 for one time constant each)."""
    g1, g2 = _inverse_noise_gain(taus1, ts), _inverse_noise_gain(taus2, ts)
    weight = g2 / (g1 + g2)
    return weight * zoh_inverse(t1, taus1, ts) + (1.0 - weight) * zoh_inverse(t2, taus2, ts)


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _rmse(estimate: np.ndarray | None, truth: np.ndarray, keep: np.ndarray) -> float | None:
    if estimate is None:
        return None
    valid = keep & np.isfinite(estimate)
    if not np.any(valid):
        return None
    diff = estimate[valid] - truth[valid]
    return float(np.sqrt(np.mean(diff * diff)))


def _taus(est: PairEstimate) -> list[list[float]]:
    return [[float(t) for t in est.time_constants[0]], [float(t) for t in est.time_constants[1]]]


def _usable(est: PairEstimate) -> bool:
    return est.status == "ok" and all(
        math.isfinite(t) and t > 0.0 for taus in est.time_constants for t in taus)


def _reconstruct(
    rec: sim.PairRecording, est: PairEstimate, reconstruction: str
) -> tuple[np.ndarray | None, str | None]:
    """Reconstruction with the estimate's time constants: (gas, error message)."""
    if not _usable(est):
        return None, f"estimate {est.status}: {est.details.get('message', '')}".strip()
    taus1, taus2 = est.time_constants
    if reconstruction == "zoh":
        return zoh_inverse_pair(rec.t1, rec.t2, rec.ts, taus1, taus2), None
    from dualprobe.reconstruction import reconstruct_pair

    try:
        gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, taus1, taus2, noise_std=est.noise_std)
    except ValueError as exc:  # reported in the table instead of stopping the report
        return None, str(exc)
    return np.asarray(gas, dtype=float), None


def _progress(values: Sequence[float], desc: str, enabled: bool) -> Iterable[float]:
    if not enabled:
        return values
    from tqdm import tqdm

    return tqdm(values, desc=desc, unit="a_p", leave=False, disable=None)  # None: TTY only


def _study_sensors(study: str, a_p: float) -> tuple[sim.SensorModel, sim.SensorModel]:
    if study == "A":
        return sim.SensorModel((paper.STUDY_A_TAU1,)), sim.SensorModel((paper.STUDY_A_TAU2, a_p))
    if study == "B":
        return sim.SensorModel(paper.STUDY_BC_TAU1), sim.SensorModel((paper.STUDY_BC_TAU2, a_p))
    raise ValueError(f"study must be 'A' or 'B', got {study!r}")


def _step_profile(
    duration: float, hold: tuple[float, float], rng: np.random.Generator, offset: float
) -> sim.GasProfile:
    """Steps of 100-300 K (random sign) every ``hold`` seconds, the first
    after 20 s, all ``offset`` off the sample grid; levels around 300 degC."""
    times = 20.0 + np.concatenate(([0.0], np.cumsum(rng.uniform(*hold, 64)))) + offset
    times = times[times < duration - 0.25 * hold[0]]
    steps = rng.choice([-1.0, 1.0], times.size + 1) * rng.uniform(100.0, 300.0, times.size + 1)
    levels = 300.0 + np.cumsum(steps)
    return sim.multistep_profile(duration, levels=levels, step_times=times)


# --------------------------------------------------------------------------------------------
# Studies A and B: first- vs second-order method on the same data
# --------------------------------------------------------------------------------------------


def compare_study(
    study: str,
    a_p_values: Sequence[float],
    *,
    noise_std: float = 0.0,
    reconstruction: str | None = None,
    on_grid: bool | None = None,
    seed: int = 0,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Study A or B (paper set-up) with the paper's method and the SVF of order 1 and 2.

    ``reconstruction``: "zoh" (exact ZOH inverse, default for noise-free data) or "smoother"
    (``reconstruct_pair`` default mode, default with noise). ``on_grid``: the gas step on a
    sample instant (the paper's set-up; default for noise-free data) or half a sample
    interval later (default with noise: a real step does not know the grid). One dict per a_p
    with the
    estimates, the RMSEs (K) of the three reconstructions, ``ratio`` = order 2 / paper and
    ``ratio_order1`` = order 2 / order 1, the order-2 identifiability and, where the order-2
    fit finds a shared pole, ``rmse_prefiltered``: against the gas temperature filtered by
    sensor 1's fast pole (study B at a_p = 0.17 s: what any two-sensor method can return).
    """
    mode = reconstruction or ("zoh" if noise_std == 0.0 else "smoother")
    if mode not in ("zoh", "smoother"):
        raise ValueError(f"compare_study: reconstruction must be zoh or smoother, got {mode!r}")
    settings = paper.STUDY
    grid = (noise_std == 0.0) if on_grid is None else on_grid
    profile = sim.step_profile(settings.t_step + (0.0 if grid else 0.5 * settings.ts),
                               settings.low, settings.high)
    rows = []
    label = f"beyond {study} ({'exact' if noise_std == 0.0 else f'{noise_std:g} K'})"
    for index, a_p in enumerate(_progress(list(a_p_values), label, progress)):
        sensor1, sensor2 = _study_sensors(study, float(a_p))
        rec = sim.simulate_pair(
            profile, sensor1, sensor2, ts=settings.ts, duration=settings.duration,
            noise_std=noise_std, rng=np.random.default_rng([seed, index]),
        )
        keep = ~rec.jump_mask(1)
        plain = paper.estimate_pair(rec.t1, rec.t2, rec.ts, method=settings.method)
        plain_gas = (paper.reconstruct_sensor1(rec.t1, plain["tau1"], rec.ts)
                     if plain["status"] == "ok" else None)
        first = characterise_pair(rec.t1, rec.t2, rec.ts, order=1)
        second = characterise_pair(rec.t1, rec.t2, rec.ts, order=2)
        gas1, error1 = _reconstruct(rec, first, mode)
        gas2, error2 = _reconstruct(rec, second, mode)
        row: dict[str, Any] = {
            "a_p": float(a_p),
            "noise_std": float(noise_std),
            "reconstruction": mode,
            "step_on_grid": grid,
            "paper_status": plain["status"],
            "paper_tau1": float(plain["tau1"]),
            "paper_tau2": float(plain["tau2"]),
            "paper_rmse": _rmse(plain_gas, rec.tg, keep),
            "order1_time_constants": _taus(first),
            "order1_rmse": _rmse(gas1, rec.tg, keep),
            "order2_time_constants": _taus(second),
            "order2_order": second.order,
            "order2_identifiable": bool(second.identifiability.get("identifiable", False)),
            "order2_sensor_orders": second.identifiability.get("sensor_orders"),
            "order2_shared_poles": second.identifiability.get("shared_poles"),
            "order2_rmse": _rmse(gas2, rec.tg, keep),
            "sensor1_rmse": _rmse(rec.t1, rec.tg, keep),
        }
        errors = [e for e in (error1, error2) if e]
        if errors:
            row["errors"] = errors
        if row["order2_shared_poles"] and len(sensor1.taus) > 1 and gas2 is not None:
            pre = sim.simulate_sensor(profile, sim.SensorModel((sensor1.taus[1],)), rec.t)
            if mode == "zoh" and grid:  # interval values: the interval mean of the filtered gas
                interval = np.full(rec.t.size, np.nan)
                interval[:-1] = rec.tg[:-1] - sensor1.taus[1] / rec.ts * np.diff(pre)
                pre = interval
            row["rmse_prefiltered"] = _rmse(gas2, pre, keep)
        for key, reference in (("ratio", "paper_rmse"), ("ratio_order1", "order1_rmse")):
            num, den = row["order2_rmse"], row[reference]
            row[key] = num / den if num is not None and den else None
        rows.append(row)
    return rows


# --------------------------------------------------------------------------------------------
# The 100 Hz second-order pair and the hysteretic pair
# --------------------------------------------------------------------------------------------


def second_order_pair(
    *, duration: float = 450.0, seed: int = 0, noise_std: float = 0.01, with_traces: bool = False
) -> dict[str, Any]:
    """The issue's 100 Hz pair: (12.30 s, 0.17 s) and (25.72 s, 1.08 s), unit gain, 100-300 K
    steps every 60-90 s off the 0.01 s grid. Order 1 and order 2 estimates and
    ``reconstruct_pair`` (default mode) with each; RMSEs against the gas temperature."""
    rng = np.random.default_rng([seed, 100])
    profile = _step_profile(duration, (60.0, 90.0), rng, 0.00371)
    rec = sim.simulate_pair(profile, *SECOND_ORDER_MODELS, ts=0.01, duration=duration,
                            noise_std=noise_std, rng=rng)
    keep = ~rec.jump_mask(1)
    out: dict[str, Any] = {"duration": duration, "sample_interval": rec.ts,
                           "noise_std": noise_std, "steps": int(rec.jumps.size),
                           "true_time_constants": [list(m.taus) for m in SECOND_ORDER_MODELS],
                           "reconstruction": "smoother"}
    gases = {}
    for order in (1, 2):
        started = time.perf_counter()
        est = characterise_pair(rec.t1, rec.t2, rec.ts, order=order)
        gas, error = _reconstruct(rec, est, "smoother")
        gases[order] = gas
        out[f"order{order}"] = {
            "time_constants": _taus(est),
            "identifiable": bool(est.identifiability.get("identifiable", False)),
            "rmse": _rmse(gas, rec.tg, keep),
            "seconds": time.perf_counter() - started,
            **({"error": error} if error else {}),
        }
    truth = np.array([12.30, 0.17, 25.72, 1.08])
    taus2 = out["order2"]["time_constants"]
    if all(len(t) == 2 for t in taus2):
        out["order2"]["relative_errors"] = list(np.abs(np.concatenate(taus2) / truth - 1.0))
    out["sensor1_rmse"] = _rmse(rec.t1, rec.tg, keep)
    r1, r2 = out["order1"]["rmse"], out["order2"]["rmse"]
    out["ratio"] = r2 / r1 if r1 and r2 is not None else None
    if with_traces:
        out["traces"] = {"t": rec.t, "tg": rec.tg, "t1": rec.t1, "t2": rec.t2,
                         "order1": gases[1], "order2": gases[2], "jumps": rec.jumps}
    return out


def hysteretic_pair(
    *, duration: float = 900.0, seed: int = 0, noise_std: float = 0.05, with_traces: bool = False
) -> dict[str, Any]:
    """10 Hz pair of hysteretic first-order sensors (:data:`HYSTERESIS_HEAT`,
    :data:`HYSTERESIS_COOL`), 100-300 K steps every 120-180 s off the grid. Hysteresis-aware
    vs plain first-order identification, and ``reconstruct_pair`` (default mode) with the
    heating/cooling time constants vs the common ones."""
    rng = np.random.default_rng([seed, 200])
    profile = _step_profile(duration, (120.0, 180.0), rng, 0.0371)
    t = 0.1 * np.arange(math.floor(duration / 0.1 + 1e-9) + 1)
    t1 = sim.simulate_hysteretic_sensor(profile, HYSTERESIS_HEAT[0], HYSTERESIS_COOL[0], t)
    t2 = sim.simulate_hysteretic_sensor(profile, HYSTERESIS_HEAT[1], HYSTERESIS_COOL[1], t)
    t1 = t1 + noise_std * rng.standard_normal(t.size)
    t2 = t2 + noise_std * rng.standard_normal(t.size)
    rec = sim.PairRecording(t=t, tg=profile(t), t1=t1, t2=t2, ts=0.1,
                            jumps=profile.jumps[profile.jumps <= t[-1]])
    keep = ~rec.jump_mask(1)
    aware = characterise_pair(t1, t2, 0.1, hysteresis=True)
    plain = characterise_pair(t1, t2, 0.1)
    truth = [HYSTERESIS_HEAT[0], HYSTERESIS_COOL[0], HYSTERESIS_HEAT[1], HYSTERESIS_COOL[1]]
    out: dict[str, Any] = {"duration": duration, "sample_interval": 0.1, "noise_std": noise_std,
                           "steps": int(rec.jumps.size), "true_heat": list(HYSTERESIS_HEAT),
                           "true_cool": list(HYSTERESIS_COOL), "reconstruction": "smoother"}
    gas_aware = None
    if aware.status == "ok" and aware.time_constants_heat and aware.time_constants_cool:
        heat, cool = aware.time_constants_heat, aware.time_constants_cool
        got = [heat[0][0], cool[0][0], heat[1][0], cool[1][0]]
        out["aware"] = {"heat": [heat[0][0], heat[1][0]], "cool": [cool[0][0], cool[1][0]],
                        "relative_errors": [abs(g / v - 1.0) for g, v in zip(got, truth,
                                                                                strict=True)],
                        "identifiable": bool(aware.identifiability.get("identifiable", False))}
        from dualprobe.reconstruction import reconstruct_pair

        gas_aware = np.asarray(reconstruct_pair(
            t1, t2, 0.1, heat[0], heat[1], taus1_cool=cool[0], taus2_cool=cool[1],
            noise_std=aware.noise_std), dtype=float)
        out["aware"]["rmse"] = _rmse(gas_aware, rec.tg, keep)
    else:
        out["aware"] = {"status": aware.status, "message": aware.details.get("message")}
    gas_plain, error = _reconstruct(rec, plain, "smoother")
    out["plain"] = {"time_constants": _taus(plain), "rmse": _rmse(gas_plain, rec.tg, keep),
                    "model_misfit": plain.identifiability.get("model_misfit"),
                    **({"error": error} if error else {})}
    out["sensor1_rmse"] = _rmse(t1, rec.tg, keep)
    if with_traces:
        out["traces"] = {"t": t, "tg": rec.tg, "t1": t1, "t2": t2, "aware": gas_aware,
                         "plain": gas_plain, "jumps": rec.jumps}
    return out


def identifiability_cases(*, seed: int = 0) -> list[dict[str, Any]]:
    """Study C (equal fast pole a_p in both sensors) noise-free and with 0.01 K: the order-2
    diagnostic should report a shared pole and the distinct time constants."""
    rows = []
    for noise in (0.0, NOISE_STD):
        for index, a_p in enumerate((0.01, 0.17, 1.08)):
            s1 = sim.SensorModel((paper.STUDY_BC_TAU1[0], a_p))
            s2 = sim.SensorModel((paper.STUDY_BC_TAU2, a_p))
            rec = sim.simulate_pair(paper.STUDY.profile(), s1, s2, ts=paper.STUDY.ts,
                                    duration=paper.STUDY.duration, noise_std=noise,
                                    rng=np.random.default_rng([seed, 300, index]))
            est = characterise_pair(rec.t1, rec.t2, rec.ts, order=2)
            rows.append({
                "case": "study C", "a_p": a_p, "noise_std": noise,
                "identifiable": bool(est.identifiability.get("identifiable", False)),
                "shared_poles": est.identifiability.get("shared_poles"),
                "gap_statistic": est.identifiability.get("gap_statistic"),
                "time_constants": _taus(est),
            })
    return rows


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)
    return path.name


def _series(rows: list[dict[str, Any]], key: str) -> tuple[list[float], list[float]]:
    pairs = [(r["a_p"], r[key]) for r in rows if r.get(key) is not None and r[key] > 0.0]
    return [p[0] for p in pairs], [p[1] for p in pairs]


def _figure_study(study: str, variants: dict[str, list[dict[str, Any]]], path: Path) -> str:
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(variants), figsize=(6 * len(variants), 5.8), squeeze=False)
    for ax, (name, rows) in zip(axes[0], variants.items(), strict=True):
        recon = "exact ZOH inverse" if rows and rows[0]["reconstruction"] == "zoh" else \
            "reconstruct_pair (smoother)"
        for key, label, style in (
            ("paper_rmse", "paper: difference GTLS + inverse of sensor 1", "o-"),
            ("order1_rmse", f"SVF order 1 + {recon}", "s--"),
            ("order2_rmse", f"SVF order 2 + {recon}", "^-"),
            ("sensor1_rmse", "sensor 1 uncompensated", ":"),
        ):
            x, y = _series(rows, key)
            if x:
                ax.loglog(x, y, style, label=label)
        x, y = _series(rows, "rmse_prefiltered")
        if x:
            ax.loglog(x, y, "kx", ms=9, label="order 2 vs T_g filtered by the shared pole")
        for value in (0.17, 1.08):
            ax.axvline(value, color="0.6", ls=":", lw=1)
        ax.set_xlabel("additional pole a_p of sensor 2 (s)")
        ax.set_ylabel("RMSE of the reconstructed gas temperature (K)")
        ax.set_title(f"study {study}, {name}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    return _save(fig, path)


def _figure_fast_pole(studies: dict[str, dict[str, list[dict[str, Any]]]], path: Path) -> str:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    lo, hi = math.inf, 0.0
    for (study, variants), colour in zip(studies.items(), ("C0", "C1"), strict=True):
        for (name, rows), marker in zip(variants.items(), ("o", "x"), strict=True):
            x = [r["a_p"] for r in rows if len(r["order2_time_constants"][1]) == 2]
            y = [r["order2_time_constants"][1][1] for r in rows
                 if len(r["order2_time_constants"][1]) == 2]
            if x:
                ax.loglog(x, y, marker, color=colour, label=f"study {study}, {name}")
                lo, hi = min(lo, *x, *y), max(hi, *x, *y)
    if hi > 0.0:
        ax.loglog([lo, hi], [lo, hi], "k:", lw=1, label="truth")
    ax.set_xlabel("true fast time constant a_p of sensor 2 (s)")
    ax.set_ylabel("identified fast time constant of sensor 2 (s)")
    ax.set_title("Second-order dual-sensor identification of the extra pole\n"
                 "(missing points: not resolved, sensor reported first order)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def _figure_traces(traces: dict[str, Any], series: list[tuple[str, str]], title: str,
                   path: Path, window: float) -> str:
    plt = _pyplot()
    jumps = np.asarray(traces["jumps"])
    centres = jumps[:2] if jumps.size else np.array([traces["t"][traces["t"].size // 2]])
    fig, axes = plt.subplots(1, centres.size, figsize=(6 * centres.size, 4.5), squeeze=False)
    t = traces["t"]
    for ax, centre in zip(axes[0], centres, strict=True):
        mask = (t >= centre - 0.1 * window) & (t <= centre + window)
        ax.plot(t[mask], traces["tg"][mask], color="k", lw=1.5, label="gas T_g (true)")
        ax.plot(t[mask], traces["t1"][mask], color="C0", lw=1, label="sensor 1")
        ax.plot(t[mask], traces["t2"][mask], color="C1", lw=1, label="sensor 2")
        for (key, label), style, colour in zip(series, ("--", "-."), ("C3", "C2"), strict=True):
            if traces.get(key) is not None:
                ax.plot(t[mask], traces[key][mask], style, color=colour, lw=1.3, label=label)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("temperature (degC)")
        ax.set_title(f"step at t = {centre:.2f} s")
        ax.legend(fontsize=7)
    fig.suptitle(title)
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"


def _fmt_taus(taus: list[list[float]]) -> str:
    return "; ".join(", ".join(f"{t:.4g}" for t in sensor) for sensor in taus)


def _study_table(rows: list[dict[str, Any]]) -> list[str]:
    lines = [
        "| a_p (s) | paper: tau1, tau2 (s) | paper RMSE (K) | order 1: taus (s) | "
        "order 1 RMSE (K) | order 2: taus (s) [sensor orders] | order 2 RMSE (K) | "
        "order 2 / paper | order 2 / order 1 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        orders = r["order2_sensor_orders"]
        note = f" [{orders[0]},{orders[1]}]" if orders else ""
        if r["order2_shared_poles"]:
            note = " [order 1: shared pole or no second pole resolved"
            if r.get("rmse_prefiltered") is not None:
                note += f"; vs filtered T_g: {_fmt(r['rmse_prefiltered'])} K"
            note += "]"
        lines.append(
            f"| {r['a_p']:g} | {r['paper_tau1']:.4g}, {r['paper_tau2']:.4g} | "
            f"{_fmt(r['paper_rmse'])} | {_fmt_taus(r['order1_time_constants'])} | "
            f"{_fmt(r['order1_rmse'])} | {_fmt_taus(r['order2_time_constants'])}{note} | "
            f"{_fmt(r['order2_rmse'])} | {_fmt(r['ratio'], 2)} | {_fmt(r['ratio_order1'], 2)} |"
        )
    return lines


def worst_ratio(
    rows: list[dict[str, Any]], limit: float = 1.08, band: tuple[float, float] | None = None
) -> tuple[float | None, float, list[float]]:
    """Largest order-2/paper RMSE ratio over a_p <= ``limit``, leaving out the records where
    the order-2 diagnostic finds a pole shared by both sensors with one time constant
    each (study B at its equal poles) and those with a_p inside ``band``: (ratio, its a_p,
    the a_p values left out). None when a ratio is missing (a failed estimate or
    reconstruction)."""
    left_out = [r["a_p"] for r in rows if r["a_p"] <= limit * (1 + 1e-9)
                and ((r["order2_shared_poles"] and r.get("rmse_prefiltered") is not None)
                     or (band is not None and band[0] <= r["a_p"] <= band[1]))]
    ratios = [(r["ratio"], r["a_p"]) for r in rows
              if r["a_p"] <= limit * (1 + 1e-9) and r["a_p"] not in left_out]
    if not ratios or any(v is None for v, _ in ratios):
        return None, math.nan, left_out
    value, a_p = max(ratios)
    return float(value), float(a_p), left_out


def _markdown(data: dict[str, Any], figures: list[str]) -> str:
    lines = [
        "The paper's conclusion (section V) that a higher-order model needs more sensors does "
        "not hold: with the gas temperature eliminated, two sensors satisfy P1(s) T1 = "
        "P2(s) T2, linear in the coefficients of both second-order denominators, and the "
        "state-variable-filter cross-relation estimator (`characterise_pair(order=2)`) "
        "identifies all four time constants from the two signals alone. Each sensor's order "
        "is chosen from the data (a sensor whose second time constant is ~0 is reported as "
        "first order).",
        "",
        "### Studies A and B with the second-order method",
        "",
        f"Same records as the paper's studies (Ts = {paper.STUDY.ts:g} s, "
        f"{paper.STUDY.duration:g} s, {paper.STUDY.low:g} -> {paper.STUDY.high:g} degC step "
        "on the sample grid), once noise-free (the paper's set-up) and once with "
        f"{NOISE_STD:g} K of white noise on each sensor. Three methods on each record: the "
        "paper's (difference-equation GTLS + exact inverse of sensor 1), the SVF of order 1 "
        "and of order 2. Reconstruction noise-free: the exact zero-order-hold inverse of each "
        "identified sensor (the paper's eq. 8 inverse generalised to second order), weighted "
        "by inverse noise gain; with noise: `reconstruct_pair` in its default mode (the "
        "smoother). RMSE against the true gas temperature at the sample instants, samples "
        "beside the jump left out.",
        "",
    ]
    for study in STUDIES:
        for name, rows in data[f"study_{study.lower()}"].items():
            band = near_equal_band(study, rows[0]["noise_std"]) if rows else None
            worst, at, left_out = worst_ratio(rows, band=band)
            excepted = (f" (left out: a_p = {', '.join(f'{v:.3g}' for v in left_out)} s, "
                        "equal or nearly equal fast poles)" if left_out else "")
            lines += [f"Study {study}, {name}: largest order-2/paper RMSE ratio for a_p <= "
                      f"1.08 s{excepted}: {_fmt(worst, 2)} at a_p = {at:g} s.", "",
                      *_study_table(rows), ""]
    lines += [
        "Study B at a_p = 0.17 s is the paper's equal-pole case: the common pole is not "
        "identifiable from two sensors (it filters the gas before both), the diagnostic says "
        "so, and every method returns at best the gas temperature filtered by it (see the "
        "pre-filtered RMSE). With 0.01 K of noise the same holds, at this sample rate and "
        "excitation, for fast poles within a factor of about 2.5 of each other (a_p = 0.07 to "
        "0.4 s in study B): the data then determine only the difference of the two fast poles "
        "(the order-2 fit reports one sensor as first order and the difference on the other, "
        "with a note) and the second-order method is about as good as the first-order one "
        "(0.01 K is 10 times too much noise to separate 0.10 s from 0.17 s with one step at "
        "10 Hz; at 0.001 K all four time constants are resolved). In study A with noise, a "
        "1 ms pole is far below what 10 Hz and "
        "0.01 K resolve: both sensors are first order within the noise, which the diagnostic "
        "reports the same way (an order-2 fit of two first-order sensors has a free common "
        "factor), and the first-order time constants are returned.",
        "",
    ]
    pair = data["second_order_100hz"]
    o1, o2 = pair["order1"], pair["order2"]
    errors = o2.get("relative_errors")
    lines += [
        "### 100 Hz pair with the paper's second-order models",
        "",
        f"Sensors 1/((1+12.30 s)(1+0.17 s)) and 1/((1+25.72 s)(1+1.08 s)), unit gain, "
        f"{pair['noise_std']:g} K noise, {pair['steps']} gas steps of 100-300 K off the "
        f"0.01 s grid, {pair['duration']:g} s. Reconstruction: `reconstruct_pair`, default "
        "mode (smoother), with each estimate's time constants.",
        "",
        "| method | time constants (s) | reconstruction RMSE (K) |",
        "|---|---|---|",
        f"| truth | 12.30, 0.17; 25.72, 1.08 | sensor 1 alone: {_fmt(pair['sensor1_rmse'])} |",
        f"| first order | {_fmt_taus(o1['time_constants'])} | {_fmt(o1['rmse'])} |",
        f"| second order | {_fmt_taus(o2['time_constants'])} | {_fmt(o2['rmse'])} |",
        "",
        f"Second/first-order RMSE ratio {_fmt(pair['ratio'], 2)}"
        + (f"; time-constant errors {', '.join(f'{100 * e:.2f} %' for e in errors)} "
           "(12.30, 0.17, 25.72, 1.08 s)." if errors else "."),
        "",
    ]
    hyst = data["hysteresis"]
    aware = hyst["aware"]
    lines += [
        "### Hysteretic pair",
        "",
        f"Both sensors heat faster than they cool: sensor 1 {HYSTERESIS_HEAT[0]:.2f} s / "
        f"{HYSTERESIS_COOL[0]:.2f} s (the paper's Figs. 15-16), sensor 2 "
        f"{HYSTERESIS_HEAT[1]:.2f} s / {HYSTERESIS_COOL[1]:.2f} s (scaled by 28.95/12.48); "
        f"10 Hz, {hyst['noise_std']:g} K, {hyst['steps']} steps of 100-300 K. Reconstruction: "
        "`reconstruct_pair` (smoother) with the heating/cooling time constants vs the "
        "plain first-order ones.",
        "",
        "| method | sensor 1 (s) | sensor 2 (s) | reconstruction RMSE (K) |",
        "|---|---|---|---|",
        f"| truth (heat / cool) | {HYSTERESIS_HEAT[0]:.3f} / {HYSTERESIS_COOL[0]:.3f} | "
        f"{HYSTERESIS_HEAT[1]:.3f} / {HYSTERESIS_COOL[1]:.3f} | sensor 1 alone: "
        f"{_fmt(hyst['sensor1_rmse'])} |",
    ]
    if "heat" in aware:
        lines.append(
            f"| hysteresis-aware (heat / cool) | {aware['heat'][0]:.3f} / {aware['cool'][0]:.3f}"
            f" | {aware['heat'][1]:.3f} / {aware['cool'][1]:.3f} | {_fmt(aware.get('rmse'))} |")
    plain = hyst["plain"]
    lines += [
        f"| plain first order | {plain['time_constants'][0][0]:.3f} | "
        f"{plain['time_constants'][1][0]:.3f} | {_fmt(plain['rmse'])} |",
        "",
    ]
    if "relative_errors" in aware:
        lines += [f"Largest error of the four hysteresis-aware time constants: "
                  f"{100 * max(aware['relative_errors']):.2f} %.", ""]
    lines += [
        "### Identifiability diagnostic",
        "",
        "| case | a_p (s) | noise (K) | identifiable | shared poles | reported (s) |",
        "|---|---|---|---|---|---|",
    ]
    for case in data["identifiability"]:
        lines.append(
            f"| {case['case']} | {_fmt(case.get('a_p'))} | {_fmt(case.get('noise_std'))} | "
            f"{case['identifiable']} | {case.get('shared_poles') or 0} | "
            f"{_fmt_taus(case['time_constants']) if case.get('time_constants') else ''} |")
    lines += ["", "In the sweeps of studies A and B the order-2 diagnostic fires at:", ""]
    for sweep in data["identifiability_sweeps"]:
        fired = ", ".join(f"{v:.3g}" for v in sweep["fired_at"]) or "none"
        lines.append(f"* study {sweep['study']}, {sweep['variant']}: a_p = {fired} "
                     f"({len(sweep['fired_at'])} of {sweep['records']} records)")
    lines += [
        "",
        "Study B at 0.17 s is the equal-pole case; study A with noise at the smallest a_p: "
        "both sensors first order within the noise (see the studies above).",
        "", "### Figures", "",
    ]
    lines += [f"* ![{name}]({name})" for name in figures]
    lines.append("")
    return "\n".join(lines)


def near_equal_band(study: str, noise_std: float) -> tuple[float, float] | None:
    """a_p values of study B whose fast pole is within a factor 2.5 of sensor 1's 0.17 s:
    with noise (0.01 K, 10 Hz, one step) the common part of the two fast poles is not
    identifiable there (measured: ratios up to 0.73 from a_p = 0.077 to 0.28 s, <= 0.012
    outside)."""
    if study != "B" or noise_std == 0.0:
        return None
    fast = paper.STUDY_BC_TAU1[1]
    return fast / 2.5, fast * 2.5


def sweeps(quick: bool) -> tuple[list[float], list[float]]:
    """a_p values for the noise-free and the noisy study runs."""
    if quick:
        return [0.001, 0.01, 0.1, 0.17, 1.08, 2.0, 5.0], [0.001, 0.01, 0.1, 0.17, 1.08]
    full = sorted({*paper.sweep_values(False), 5.0})
    return full, full


def run_beyond(
    quick: bool, out_dir: str | Path, *, progress: bool = True, seed: int = 0
) -> tuple[str, dict[str, Any]]:
    """Run the "Beyond the paper" studies, write the figures into ``out_dir`` and return
    (Markdown section, JSON data). ``quick``: a handful of a_p values, shorter records."""
    started = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    exact_values, noisy_values = sweeps(quick)
    data: dict[str, Any] = {}
    for study in STUDIES:
        data[f"study_{study.lower()}"] = {
            "noise-free": compare_study(study, exact_values, seed=seed, progress=progress),
            f"{NOISE_STD:g} K noise": compare_study(study, noisy_values, noise_std=NOISE_STD,
                                                    seed=seed, progress=progress),
        }
    pair = second_order_pair(duration=120.0 if quick else 450.0, seed=seed, with_traces=True)
    hyst = hysteretic_pair(duration=600.0 if quick else 1500.0, seed=seed, with_traces=True)
    cases = identifiability_cases(seed=seed)
    cases.append({"case": "100 Hz pair above", "a_p": None, "noise_std": pair["noise_std"],
                  "identifiable": pair["order2"]["identifiable"], "shared_poles": None,
                  "time_constants": pair["order2"]["time_constants"]})
    if "identifiable" in hyst["aware"]:
        cases.append({"case": "hysteretic pair above", "a_p": None,
                      "noise_std": hyst["noise_std"],
                      "identifiable": hyst["aware"]["identifiable"], "shared_poles": None,
                      "time_constants": []})
    data["identifiability"] = cases
    data["identifiability_sweeps"] = [
        {"study": study, "variant": name, "records": len(rows),
         "fired_at": [r["a_p"] for r in rows if not r["order2_identifiable"]]}
        for study in STUDIES for name, rows in data[f"study_{study.lower()}"].items()
    ]
    traces_pair = pair.pop("traces")
    traces_hyst = hyst.pop("traces")
    data["second_order_100hz"] = pair
    data["hysteresis"] = hyst
    figures = [
        _figure_study("A", data["study_a"], out / "beyond_study_a.png"),
        _figure_study("B", data["study_b"], out / "beyond_study_b.png"),
        _figure_fast_pole({s: data[f"study_{s.lower()}"] for s in STUDIES},
                          out / "beyond_fast_pole.png"),
        _figure_traces(traces_pair, [("order1", "first-order method (reconstruct_pair)"),
                                     ("order2", "second-order method (reconstruct_pair)")],
                       "100 Hz pair, second-order Pt-100 models: reconstructions",
                       out / "beyond_100hz_reconstruction.png", 8.0),
        _figure_traces(traces_hyst, [("plain", "plain first-order identification"),
                                     ("aware", "hysteresis-aware identification")],
                       "Hysteretic pair (heating faster than cooling): reconstructions",
                       out / "beyond_hysteresis.png", 60.0),
    ]
    data["figures"] = figures
    data["settings"] = {"quick": quick, "seed": seed, "noise_std": NOISE_STD,
                        "studies": asdict(paper.STUDY),
                        "seconds": time.perf_counter() - started}
    return _markdown(data, figures), data
