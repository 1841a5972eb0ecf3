"""Noise-robust reconstruction of the gas temperature from a sensor pair (design section 4).

:func:`reconstruct_pair` (:mod:`~dualprobe.reconstruction.pair`) is the entry point;
:func:`fit_smoother` (:mod:`~dualprobe.reconstruction.smoother`) returns everything the
smoother found.

Both sensors are measurements of one state-space model
(:mod:`~dualprobe.reconstruction.statespace`, discretised by the compiled core): the gas
temperature is a random walk (``rw``) or an integrated random walk (``irw``) in continuous
time, each sensor a chain of first-order stages, discretised exactly (Van Loan), so the gas
state is the gas temperature AT each sample instant (no half-sample shift). Time constants that
follow the gas flow (a schedule per sample) give one discretisation per schedule level.

``mode="smoother"`` (offline, default): the maximum a-posteriori gas trajectory given all
samples, with Student-t (nu = 1) gas increments so that a step between two samples costs
~log(size) instead of size^2 and stays sharp, while slow motion is smoothed as by a Gaussian
(RTS) smoother. Solved as one banded least-squares problem per evaluation (the normal equations
of the whole trajectory are block-tridiagonal, bandwidth 2n - 1: LAPACK ``dpbtrf``/``dpbtrs``),
the Student-t prior by iteratively reweighted least squares (weights ``(nu + n)/(nu + m_k^2)``,
m_k^2 the Mahalanobis size of increment k). Chosen from the data, nothing tuned by hand:

* the noise level of each sensor, when not given: MAD of its third differences, floored at
  1e-9 of the signal scale; plus, per sensor, the lag of a stage merged away (below) times
  the RMS rate of its output (the merged model's own error, ~ that lag x dT/dt);
* the gas intensity q: start at the maximum of the Gaussian model's marginal likelihood
  (exact, from the same banded Cholesky: ``-log p(y) = J(x_hat) + 1/2 log det A -
  N n/2 log 2 pi``); then rounds of (weights from the current increments, one safeguarded
  Newton step on log q of that likelihood with the weights co-moving with q) until the
  trajectory changes by less than 1 % of the noise or the best nll gains less than 1 over two
  rounds (at most 25 rounds; the best round kept);
* rw or irw: rw is fitted first, then irw starting from rw's weights where they mark jumps
  (min(weight, 1)): from all-equal weights irw smears a step into a ramp and the reweighting
  keeps it there (1.2 K on noise-free study B). The better marginal likelihood wins; irw is
  abandoned once it cannot reach rw's at its recent rate of improvement. (Choosing after 3
  rounds, as before, picked irw on noise-free data whose nll was still falling by 1e4.)
* the noise level once more: if the chosen fit needs a run of more than ``_MAX_JUMP_REGION``
  consecutive jump intervals, the model disagrees with the samples by more than the noise
  (typically identified time constants 1e-5 off on noise-free data); that disagreement is
  noise to the model, so the noise level is raised 10x and the fit repeated (at most 6 x).

Fast stages. A stage much faster than the sample interval is unresolvable in the samples: after
a few of its own time constants it acts as a sub-sample delay. The Van Loan discretisation of
:func:`~dualprobe.reconstruction.statespace.pair_model` (``expm`` of a matrix holding ``-F``)
loses digits below tau = Ts/30 and breaks down below ~Ts/60 (measured: unit process covariance
exact to 1e-16 at Ts/20, 1e-9 at Ts/50, eigenvalue -2e15 at Ts/100, for one and two
second-order sensors, rw and irw). So the model-based modes merge a second stage faster than
``STAGE_MERGE_FRACTION`` Ts = Ts/20 into the sensor's other stage with the SUM of the time
constants kept (:func:`~dualprobe.reconstruction.stages.resolvable_stages`): that keeps the
first moment of the impulse response (the lag on a ramp) exactly; what remains, ``-a b s^2 /
((1 + a s)(1 + b s)(1 + (a + b) s))``, is at most ~b/a of a step in the sensor output (0.002 s
/ 25 s of a 100 K step: 0.008 K) and is taken as noise (above). A lone stage faster than Ts/20
is raised to it. Faster stages above Ts/20 stay in the exact model; for them the model-error
floor of the causal filter grows as (Ts/tau)^2 and cut sensor 2 off the gas (a_p = 0.002-0.02
s at 10 Hz, 0.01 K, smooth gas: up to 8x worse than without the stage), so the smoother uses
its own floor with ``1 - exp(-Ts/tau)`` instead of Ts/tau
(:func:`~dualprobe.reconstruction.statespace.process_floor`; the same for tau >> Ts). The
causal filter (the core's Kalman filter) keeps its own floor, with the merged stages.

Steps on a sample instant (right-continuity). A gas step exactly at t_k (the paper's studies,
zero-order-hold data) leaves the outputs at t_k untouched; the samples cannot tell it from a
step just after t_k, and the smoother's value at t_k is the level before. The gas is taken
right-continuous (as :class:`dualprobe.simulate.GasProfile` and eq. 8's held input), so each
jump region (consecutive intervals weighted as jumps) is tested for one step at an instant
(``steps_at_samples`` in :mod:`~dualprobe.reconstruction.smoother`: exact step response of the
continuous model against the outputs, chi-square tests; a position within 10 % of Ts of the
instant counts as on it, since slightly wrong time constants shift it by a few %). Where it
passes, the samples from the instant on carry the level after the step
(``SmootherFit.steps_at_samples``). Off-grid steps are unaffected; the samples beside any step
remain the uncertain ones.

``mode="filter"`` (causal, as on the ECU): the core's Kalman filter
(:func:`~dualprobe.reconstruction.statespace.causal_filter`) with GLR jump detection, run with
the gas model, the merged stages, the noise levels and the background intensity (q / median
weight) that the smoother identified on the record (on an ECU these are configuration
constants). Causal: at a step on an instant it reports the level before (the samples show
nothing yet).

``mode="inverse"``: the exact inverse of each whole ZOH-sampled sensor
(:func:`dualprobe.models.inverse.zoh_inverse`, the paper's eq. 8 inverse generalised to 1 or 2
stages: exact when the gas is constant over each interval, however fast a stage), aligned to
the sample instants (mean of the two held values around t_k) and combined with inverse-variance
weights (the aligned inverse's noise gain); NaN at the first and last sample. Its noise gain is
~tau/Ts per sensor (10^4-10^7 for second-order Pt-100s at 10 Hz): the noisy comparison.

Hysteresis (``taus*_cool``): each stage uses its cooling time constant while its input is
below its state; the smoother re-evaluates the modes on its own trajectory until they settle.

Static gains (``relative_static``): the sensors are unit-gain by default (design.md). The
paper's Pt-100s have 0.99 and 1.03; ``characterise_pair`` can identify the ratio and an
offset (affine static model); with them sensor 2 is referred to sensor 1's calibration and
the reconstruction is sensor 1's reading of the gas (its gain and offset cannot be told from
two sensors alone).
"""

from __future__ import annotations

from dualprobe.reconstruction.pair import MODES, Reconstruction, reconstruct, reconstruct_pair
from dualprobe.reconstruction.resolution import Bandwidth, bandwidth
from dualprobe.reconstruction.smoother import SmootherFit, fit_smoother
from dualprobe.reconstruction.stages import resolvable_stages

__all__ = [
    "MODES",
    "Bandwidth",
    "Reconstruction",
    "SmootherFit",
    "bandwidth",
    "fit_smoother",
    "reconstruct",
    "reconstruct_pair",
    "resolvable_stages",
]
