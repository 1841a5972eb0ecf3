"""The flow column's own noise: what it does to a flow law, and how much of a misfit it explains.

An ECU's exhaust mass flow (an air-mass meter plus the fuel, or a model of them) carries noise of
its own, and a flow law passes it into the time constants: ``log psi = m log(v / v_ref)`` moves
by m times the column's noise on every row. Measured on the separate generator
(``tests/python/field_independent.py``, 10 Hz, 20 min, sheaths 0.4 / 0.3 s, 3 % white noise on
the mass flow): the misfit rose from 1.05 to 1.41 times the noise (11 standard deviations), the
sheaths came out 13 % longer and the gas 1.20x the oracle (1.03x with the clean column).
Smoothing the column does not restore it: a Savitzky-Golay or Gaussian filter that halved the
noise left the same misfit and gas (1.20-1.23x), while half the noise itself gave 1.07x; the
damage is done by the noise inside the band where the flow itself moves, which no filter of the
column can tell from the flow. So the column's noise is measured and reported, it enters the
gas's uncertainty, and the model check names it when it explains the misfit.

* :func:`column_noise`: the white noise of ``log v`` from its differences (the package's one
  noise estimator, with its quantisation floor), at the column's refreshes when it is held.
* :func:`noise_evidence`: the column's noise for the law's evidence (the schedule's row noise
  is ``|m|`` times it, ``FlowModel.psi_flow_noise``) and, where the fit misfits, how much
  misfit the column's noise adds: the fit repeated on the schedule with as much noise again
  (the misfit is a variance ratio, to first order ``1 + c s^2``, so adding the same ``s^2``
  once more adds the share already in it). It errs low: on the sheathed pair above it gave
  49 % where the clean column's misfit shows 87 % (the stages absorb part of what is added).
"""

from __future__ import annotations

import math

import numpy as np

from dualprobe.estimation.field import FlowModel, explains_data, fit_of, scheduled_misfit
from dualprobe.estimation.result import PairEstimate
from dualprobe.models.held import MAX_REFRESH, refreshes
from dualprobe.models.noise import ORDER_ESTIMATION, estimate_noise_std

__all__ = ["column_noise", "noise_evidence"]

_SEED = 20261205  # the added noise is a fixed draw: the same record gives the same evidence


def column_noise(values: np.ndarray, ts: float) -> float:
    """White-noise standard deviation of ``log values`` (relative noise of the flow column):
    from its ``ORDER_ESTIMATION``-th differences (the flow is smooth on the rows like the
    sensors' readings), taken at the column's refreshes when a logger held it
    (:func:`dualprobe.models.held.refreshes`, as ``unhold`` finds them), because a held
    value repeats one reading's noise. NaN for a column too short to tell."""
    v = np.asarray(values, dtype=float)
    points, refresh = refreshes(v, ts, MAX_REFRESH)
    if refresh > 1:
        v = v[points]
    if v.size < ORDER_ESTIMATION + 2:
        return math.nan
    return estimate_noise_std(np.log(v), ORDER_ESTIMATION)


def noise_evidence(t1: np.ndarray, t2: np.ndarray, estimate: PairEstimate, model: FlowModel,
                   noise: float) -> dict[str, float]:
    """The evidence entries for a flow column of relative noise ``noise``
    (:func:`column_noise`) under the law ``model`` fitted as ``estimate``: ``flow_noise`` the
    column's (the schedule's row noise is ``model.psi_flow_noise``, ``|m|`` times it) and,
    when the fit misfits (as the model check judges it), ``misfit_flow_noise``: the misfit (in
    units of the noise variance) that the column's noise adds, measured by adding as much
    again."""
    if not (model.scheduled and model.column is not None and math.isfinite(noise)):
        return {}
    row_noise = abs(model.exponent) * noise
    found = {"flow_noise": noise}
    if row_noise > 0.0 and not explains_data(estimate):
        fit = fit_of(estimate)
        draw = np.random.default_rng(_SEED).standard_normal(model.psi.size)
        again = scheduled_misfit(t1, t2, fit, model.psi * np.exp(row_noise * draw))
        if math.isfinite(again):
            found["misfit_flow_noise"] = max(again - fit.misfit, 0.0)
    return found
