"""Transfer-function identification from a reference measurement to a sensor output.

What MATLAB's ``tfest`` / ``compare`` give, for the models of the paper's Tables I and II:

* order 1: ``K / (1 + tau s)``
* order 2: ``K / ((1 + tau_a s)(1 + tau_b s))`` (``tau_a >= tau_b``)

each optionally with a dead time ``exp(-theta s)`` and an output offset.

Plunge tests (no reference column: an ideal step at an unknown instant) are fitted by
:func:`fit_step` (:mod:`~dualprobe.identify.step`), which returns a :class:`StepFit`.

:func:`fit_transfer_function` (:mod:`~dualprobe.identify.fit`) returns a :class:`TfFit`
(:mod:`~dualprobe.identify.result`); :func:`simulate_fit` and :func:`simulate_model`
(:mod:`~dualprobe.identify.model`) simulate it.

Method: output-error fitting. The continuous model is discretised *exactly* for an input that
is linear between samples (first-order hold, the default: a measured reference temperature is
smooth) or constant between samples (zero-order hold); a fractional dead time is handled
exactly by splitting the sample interval at the delayed sample instant. The discrete model is
simulated with :func:`scipy.signal.lfilter`. The initial state is estimated (one value per
state, in output units), not assumed zero. The gain and the initial state enter linearly, so
the search over the time constants and the dead time uses variable projection (the linear
parameters are solved for at every trial) from a coarse multi-start grid; the best candidate is
then polished with :func:`scipy.optimize.least_squares` over all parameters.

Uncertainties are the usual 1-sigma values ``sqrt(diag(s^2 (J^T J)^-1))`` with ``J`` the
Jacobian of the simulated output with respect to the reported parameters and ``s^2`` the
residual variance. They assume white residuals; with autocorrelated residuals (model error,
coloured noise) they are optimistic, which is why the lag-1 autocorrelation of the residuals
is reported alongside.
"""

from __future__ import annotations

from dualprobe.identify.fit import fit_transfer_function
from dualprobe.identify.model import simulate_fit, simulate_model
from dualprobe.identify.result import (
    GAIN_RANGE,
    HOLDS,
    INITIAL_CONDITIONS,
    IdentificationError,
    TfFit,
    check_gain,
)
from dualprobe.identify.step import StepFit, fit_step

__all__ = [
    "GAIN_RANGE",
    "HOLDS",
    "INITIAL_CONDITIONS",
    "IdentificationError",
    "StepFit",
    "TfFit",
    "check_gain",
    "fit_step",
    "fit_transfer_function",
    "simulate_fit",
    "simulate_model",
]
