"""Do the data determine a tracked schedule? A rival that explains both signals as well.

Without a flow signal, psi is seen only where the two readings differ while the gas moves (at
first order ``psi = (tau1 y1' - tau2 y2') / (y2 - y1)``). Where the readings coincide while the
gas and the flow move together, as an exhaust's load moves both, a change of psi and a change of
the gas explain the readings alike, and the tracked psi there is what its regularisation made
it. The even/odd split (``psi_noise``) cannot see this: both halves share the gap. Measured on
the separate generator (tests/python/field_independent.py, a nearly unsheathed pair of 6.5 /
14.1 s elements, m 0.62, 10 Hz): where a cruise's 0.2 Hz speed wobble moved the gas by +-25 K
and psi by +-30 % while the readings coincided, the tracked time constants were 25 % RMS off
and the gas 5.3x the oracle's error, reported as explaining the data.

So a rival schedule is made by another estimator with other priors: the joint MAP of the gas,
the states and psi (:class:`~dualprobe.estimation.map_schedule.MapSchedule`) given the tracked
stages and static map, fitted by the same engine at the tracked order; the farthest schedule
from the tracked one towards it that explains the data (as the model check judges it) is the
rival. Where there is one, the data cannot choose between the two schedules, and
any estimate of the gas lies at least half their gases' distance from one of them: the
reconstruction's uncertainty covers that half-difference, and the model check doubts a record
where it exceeds the uncertainty stated without it (:mod:`dualprobe.workflows.characterise`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from dualprobe.estimation.field import FlowModel, RunSvf, explains_data, fit_of
from dualprobe.estimation.map_schedule import MapSchedule
from dualprobe.estimation.result import PairEstimate

__all__ = ["rival_schedule"]


def rival_schedule(t1: np.ndarray, t2: np.ndarray, chosen: PairEstimate, model: FlowModel,
                   run: RunSvf) -> FlowModel:
    """``model`` with its :attr:`FlowModel.rival` set (the engine's fit on the rival schedule,
    that schedule as its flow model) where ``model`` is a first-order tracked schedule (not the
    sheathed path, which is doubted anyway) and a schedule between it and the MAP's explains
    the data; else ``model`` unchanged. The rival's misfit and how far it went towards the
    MAP's schedule go to ``evidence["misfit_rival"]`` and ``evidence["rival_share"]``."""
    if model.kind != "tracked" or model.sheathed_path or model.tracking is None:
        return model
    fit = fit_of(chosen)
    maps = MapSchedule(t1, t2, fit)
    if not maps.usable:
        return model
    try:
        maps.set_model(model.tracking.static, chosen.time_constants[0][0])
    except ValueError:
        return model
    # the stage that sees the gas first (the shorter) first, as the MAP takes them
    far = maps.schedule([tuple(sorted(taus)) for taus in chosen.time_constants])
    if far is None:
        return model
    # The farthest schedule towards the MAP's that still explains the data (as the model
    # check judges it: by its own effective rows): the tracked schedule minimises the engine's
    # misfit, so the MAP's own may lie just outside what the data allow (a 10 Hz pair: 1.70
    # times the noise, 12.5 deviations, where the tracked one is at 1.11).
    towards = np.log(far) - np.log(model.psi)
    evidence = dict(model.evidence)
    # at the tracked fit's order: a 2 Hz pair's rival at order 2 took a stage of 128.5 s
    # shared by both sensors (a common factor absorbing the difference), its gas 3,180 K off
    order = max(len(taus) for taus in chosen.time_constants)
    for share in _SHARES:
        psi = model.psi * np.exp(share * towards)
        estimate = run(psi, order)
        if estimate.status != "ok":
            continue
        if explains_data(estimate):
            evidence.update(misfit_rival=fit_of(estimate).misfit, rival_share=share)
            rival = dataclasses.replace(estimate, flow_model=FlowModel("tracked", psi))
            return dataclasses.replace(model, evidence=evidence, rival=rival)
    return model


# how far towards the MAP's schedule (in log psi) the rival is tried, farthest first
_SHARES = (1.0, 0.75, 0.5, 0.25)
