"""`dualprobe characterise --report DIR`: the figures of one characterisation.

- ``reconstruction.png``: both sensors, the reconstructed gas temperature and its +-2 sigma
  band (the smoother's posterior standard deviation), and the reference when given;
- ``tau_flow.png`` (a flow law was identified): each sensor's dominant time constant against
  the flow: constant-tau fits of overlapping windows (the data), the identified law and its
  +-1 sigma band (the time constant's and the exponent's standard uncertainties, combined in
  log space as if independent);
- ``tau_time.png`` (time constants tracked or scheduled): the time constants in effect at each
  row.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from dualprobe.estimation.field import windowed_time_constants
from dualprobe.report.plots import figure, save
from dualprobe.workflows.characterisation import Characterisation

__all__ = ["write_report"]


def _reconstruction(result: Characterisation, signals: tuple[np.ndarray, np.ndarray],
                    reference: np.ndarray | None, path: Path) -> str:
    fig, axes = figure(10.0, 5.0)
    ax = axes[0, 0]
    t = result.time
    ax.plot(t, signals[0], lw=0.7, label=result.columns[0])
    ax.plot(t, signals[1], lw=0.7, label=result.columns[1])
    if reference is not None:
        ax.plot(t, reference, lw=0.7, color="k", label=f"{result.reference_column} (reference)")
    if result.gas_estimate is not None:
        ax.plot(t, result.gas_estimate, lw=0.8, color="C3", label="gas (reconstructed)")
        if result.gas_std is not None:
            ax.fill_between(t, result.gas_estimate - 2.0 * result.gas_std,
                            result.gas_estimate + 2.0 * result.gas_std, color="C3", alpha=0.25,
                            lw=0, label="±2σ" if result.bandwidth is None else
                            f"±2σ (gas resolved to {result.bandwidth.hz:.3g} Hz)")
    ax.set_xlabel("time / s")
    ax.set_ylabel("temperature")
    ax.legend(loc="best", fontsize=8)
    return save(fig, path, tight=False)


def _tau_flow(result: Characterisation, signals: tuple[np.ndarray, np.ndarray],
              path: Path) -> str | None:
    est = result.estimate
    model = est.flow_model
    if model is None or result.flow is None or model.kind not in ("power_law", "curve"):
        return None
    flows, window_taus = windowed_time_constants(signals[0], signals[1], est, result.flow)
    low, high = model.flow_range or (float(np.min(result.flow)), float(np.max(result.flow)))
    grid = np.geomspace(low, high, 60)
    if model.kind == "curve" and model.curve is not None:
        psi = model.curve.psi(grid)
    else:
        psi = (grid / float(model.reference_flow)) ** model.exponent
    conf = est.confidence
    m_std = conf.std.get("exponent", math.nan) if conf is not None else math.nan
    if not math.isfinite(m_std):
        m_std = model.exponent_std
    fig, axes = figure(10.0, 4.5, cols=2)
    for i in range(2):
        ax = axes[0, i]
        tau = est.time_constants[i][0] / psi
        ax.plot(grid, tau, color=f"C{i}", label=f"{model.kind.replace('_', ' ')}")
        tau_std = conf.std.get(f"tau{i + 1}_0", math.nan) if conf is not None else math.nan
        rel = tau_std / est.time_constants[i][0] if math.isfinite(tau_std) else 0.0
        log_ratio = np.log(grid / float(model.reference_flow))
        spread = np.sqrt(rel**2 + (log_ratio * (m_std if math.isfinite(m_std) else 0.0)) ** 2)
        ax.fill_between(grid, tau * np.exp(-spread), tau * np.exp(spread), color=f"C{i}",
                        alpha=0.25, lw=0, label="±1σ")
        if flows.size:
            ax.plot(flows, window_taus[:, i], "o", ms=3, color="0.3",
                    label="windows (constant-tau fits)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"{model.column or 'flow'}")
        ax.set_ylabel(f"tau of {result.columns[i]} / s")
        ax.legend(loc="best", fontsize=8)
    return save(fig, path, tight=False)


def _tau_time(result: Characterisation, path: Path) -> str | None:
    model = result.estimate.flow_model
    if model is None or not model.scheduled:
        return None
    tau1, tau2 = result.time_constants_per_row()
    fig, axes = figure(10.0, 4.0)
    ax = axes[0, 0]
    ax.plot(result.time, tau1, lw=0.8, label=f"tau of {result.columns[0]}")
    ax.plot(result.time, tau2, lw=0.8, label=f"tau of {result.columns[1]}")
    ax.set_xlabel("time / s")
    ax.set_ylabel("time constant / s")
    ax.set_title(f"time constants in effect ({model.kind.replace('_', ' ')})")
    ax.legend(loc="best", fontsize=8)
    return save(fig, path, tight=False)


def write_report(result: Characterisation, directory: str | os.PathLike[str]) -> list[str]:
    """Write the figures (module docstring) into ``directory``; returns the file names."""
    if result.signals is None:
        raise ValueError("write_report: the characterisation carries no signals")
    signals, reference = result.signals, result.reference
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    names = [_reconstruction(result, signals, reference, out / "reconstruction.png")]
    for name in (_tau_flow(result, signals, out / "tau_flow.png"),
                 _tau_time(result, out / "tau_time.png")):
        if name is not None:
            names.append(name)
    return names
