"""The discrepancy workflow (issue 5): where do simulation and measurement disagree, which
catalogued effect is missing, add it, and show the gap shrink.

:func:`diagnose` (:mod:`~dualprobe.diagnose.search`) returns a :class:`Diagnosis`
(:mod:`~dualprobe.diagnose.result`); :func:`diagnose_file` and :func:`write_json`
(:mod:`~dualprobe.diagnose.files`) read a CSV recording and write the JSON document,
:mod:`~dualprobe.diagnose.report` the Markdown report. The model family is simulated in
:mod:`~dualprobe.diagnose.model` and fitted in :mod:`~dualprobe.diagnose.fit`; the effects it
can be extended by are in :mod:`~dualprobe.diagnose.catalogue`, the residual tests and the
localisation in :mod:`~dualprobe.diagnose.residuals`.

Input: the reference (fast) measurement of the gas temperature ``u`` and the output ``y`` of the
sensor under test, sampled at ``ts``. The model family, all nested extensions of the paper's
first-order unity-gain sensor::

    v(t)  = u(t - delay)                                   dead_time
    x1    = 1/(1 + tau s) v        (tau_heat / tau_cool     hysteresis: tau by heat-flow direction)
    x     = 1/(1 + tau2 s) x1                               extra_pole
    y_hat = x + offset + (gain - 1) x + curvature x (x - 100)     offset, gain, nonlinearity

The reference is interpolated linearly between samples (first-order hold), so gas changes between
samples cost no systematic delay, or held over each sample interval when the data follow the
paper's eq. 8 (decided by the better fit, again with every model reached); the dynamics are
discretised exactly for either. The static map is linear in its parameters and solved exactly
for every trial of the dynamics (variable projection); the dynamics are fitted by
Levenberg-Marquardt. ``curvature x (x - 100)`` (degC) is the shape of a Pt-100 read through the
linear alpha conversion: Callendar-Van Dusen gives ``T_read - T = (B/alpha) T (T - 100)``.

Decision (per step, over the catalogue): each candidate extension of the current model is
fitted; it is *statistically significant* when the likelihood ratio, computed with an effective
sample size from the candidate's residual autocorrelation (long-run variance), passes both a
chi-square test at ``SIGNIFICANCE_LEVEL`` and the BIC penalty; *practically significant* when
it closes at least ``MIN_GAP_CLOSED`` of the remaining gap (mean square residual above the floor
a perfect model leaves: white noise plus the residue of gas jumps between samples), improves by
at least ``MIN_IMPROVEMENT_OF_NOISE`` of the noise variance, the effect is at least
``MIN_EFFECT_SIZE`` large, and, for a static effect, it also improves the settled samples. Among
significant candidates the best wins unless a simpler one (``SIMPLICITY`` order) does nearly as
well. When none is significant but a large gap remains, pairs (one static) are tested jointly,
since a gain error can cancel a curvature or a hysteresis bias. Repeat until nothing significant
remains; an effect whose removal from the final model is itself insignificant is dropped and the
ladder rebuilt.
"""

from __future__ import annotations

from dualprobe.diagnose.catalogue import EFFECTS, FITTED_EFFECTS, SIMPLICITY, UNITS
from dualprobe.diagnose.catalogue.dynamics import hysteretic_first_order, simulate_hysteretic
from dualprobe.diagnose.evidence import MIN_GAP_CLOSED, SIGNIFICANCE_LEVEL
from dualprobe.diagnose.files import diagnose_file, write_json
from dualprobe.diagnose.fit import ModelFit, fit_model
from dualprobe.diagnose.floors import roughness_floor, sampling_floor
from dualprobe.diagnose.localise import localise
from dualprobe.diagnose.model import simulate_effects
from dualprobe.diagnose.report import FIGURES, REPORT_NAME, write_report
from dualprobe.diagnose.residuals import residual_tests
from dualprobe.diagnose.result import Diagnosis, Step
from dualprobe.diagnose.search import diagnose
from dualprobe.diagnose.verdict import MISFIT_LIMIT, VERDICTS, Verdict

__all__ = [
    "EFFECTS",
    "FIGURES",
    "FITTED_EFFECTS",
    "MIN_GAP_CLOSED",
    "MISFIT_LIMIT",
    "REPORT_NAME",
    "SIGNIFICANCE_LEVEL",
    "SIMPLICITY",
    "UNITS",
    "VERDICTS",
    "Diagnosis",
    "ModelFit",
    "Step",
    "Verdict",
    "diagnose",
    "diagnose_file",
    "fit_model",
    "hysteretic_first_order",
    "localise",
    "residual_tests",
    "roughness_floor",
    "sampling_floor",
    "simulate_effects",
    "simulate_hysteretic",
    "write_json",
    "write_report",
]
