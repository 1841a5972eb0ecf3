"""The figures of the paper reproduction (Figs. 3-5, 7-9, 11, 13, 15-16)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from dualprobe import simulate as sim
from dualprobe.identify import TfFit, simulate_fit
from dualprobe.report.plots import pyplot, save
from dualprobe.studies.paper_setup import (
    RIG,
    SENSOR_LABELS,
    STUDY,
    STUDY_A_TAU1,
    STUDY_A_TAU2,
    StudySettings,
    study_record,
)

__all__ = [
    "figure_fig5",
    "figure_hysteresis",
    "figure_models",
    "figure_reconstruction",
    "figure_sweep",
]


def figure_models(records: dict[str, Any], order_key: str, path: Path, title: str) -> str:
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    for row, (name, rec) in enumerate(records.items()):
        fit: TfFit = rec["fit_" + order_key]
        t = rec["t"]
        for col, window in enumerate(((t[0], t[-1]), (RIG.t_step - 0.5, RIG.t_step + 4.0))):
            ax = axes[row, col]
            mask = (t >= window[0]) & (t <= window[1])
            ax.plot(t[mask], rec["u"][mask], color="0.6", lw=0.8, label="reference T_mref")
            ax.plot(t[mask], rec["y"][mask], color="C0", lw=1.0, label="Pt-100 (simulated)")
            ax.plot(t[mask], rec[order_key][mask], "--", color="C3", lw=1.2, label=fit.model)
            ax.set_xlabel("time (s)")
            ax.set_ylabel("temperature (degC)")
            zoom = " (zoom on the step)" if col else ""
            ax.set_title(f"{SENSOR_LABELS[name]}{zoom}: fit {fit.fit_percent:.2f} %")
            ax.legend(fontsize=8, loc="lower right")
    fig.suptitle(title)
    return save(fig, path)


def figure_fig5(settings: StudySettings, path: Path) -> str:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    first = None
    for a_p, style in ((0.001, "-"), (0.17, "--"), (1.08, ":")):
        rec = study_record(
            sim.SensorModel((STUDY_A_TAU1,)), sim.SensorModel((STUDY_A_TAU2, a_p)), settings
        )
        if first is None:
            first = rec
            ax.plot(rec.t, rec.tg, color="k", lw=1, label="gas T_g")
            ax.plot(rec.t, rec.t1, color="C0", label="T_m1: 1/(1+12.48s)")
        ax.plot(rec.t, rec.t2, style, color="C1", label=f"T_m2: 1/((1+{a_p}s)(1+28.95s))")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("temperature (degC)")
    ax.set_title("Fig. 5: simulated Pt-100 outputs (first- and second-order models)")
    ax.legend()
    return save(fig, path)


def figure_sweep(
    series: list[tuple[list[dict[str, Any]], str, str, str]],
    path: Path,
    title: str,
    marks: dict[str, float],
) -> str:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    for rows, key, label, style in series:
        a_p = [r["a_p"] for r in rows if r.get(key) is not None]
        val = [r[key] for r in rows if r.get(key) is not None]
        ax.loglog(a_p, val, style, label=label)
    for name, value in marks.items():
        ax.axvline(value, color="0.5", ls=":", lw=1)
        ax.text(value, ax.get_ylim()[0], f" {name}\n a_p={value}", va="bottom", fontsize=8)
    ax.set_xlabel("additional pole a_p (s)")
    ax.set_ylabel("RMSE of the reconstruction (K)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return save(fig, path)


def figure_reconstruction(trace: dict[str, Any], a_p: float, path: Path, number: int) -> str:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    t = trace["t"]
    est = trace["estimate"]
    for ax, window in zip(axes, ((0.0, t[-1]), (STUDY.t_step - 2, STUDY.t_step + 20)), strict=True):
        mask = (t >= window[0]) & (t <= window[1])
        ax.plot(t[mask], trace["tg"][mask], color="k", lw=1.2, label="gas T_g (true)")
        ax.plot(t[mask], trace["t1"][mask], color="C0", label="T_m1")
        ax.plot(t[mask], trace["t2"][mask], color="C1", label="T_m2")
        ax.plot(t[mask], trace["tgr"][mask], "--", color="C3", label="reconstructed T_gr")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("temperature (degC)")
        ax.legend(fontsize=8)
    tau1 = est.get("tau1", math.nan)
    axes[0].set_title(f"Fig. {number}: a_p = {a_p} s, tau1 est. {tau1:.3f} s (true 12.48)")
    axes[1].set_title("zoom on the step")
    return save(fig, path)


def figure_hysteresis(rec: dict[str, Any], path: Path, title: str, true_tau: float) -> str:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 5))
    fit: TfFit = rec["fit"]
    ax.plot(rec["t"], rec["u"], color="0.6", lw=0.8, label="reference T_mref")
    ax.plot(rec["t"], rec["y"], color="C0", label="1.5 mm Pt-100 (simulated, hysteretic)")
    ax.plot(
        rec["t"],
        simulate_fit(fit, rec["u"]),
        "--",
        color="C3",
        label=f"first-order fit: tau = {fit.taus[0]:.2f} s (true {true_tau})",
    )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("temperature (degC)")
    ax.set_title(title)
    ax.legend()
    return save(fig, path)
