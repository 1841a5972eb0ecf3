"""Identification of a sensor pair's time constants from its two signals alone.

:func:`characterise_pair` (:mod:`~dualprobe.estimation.pair`) returns a :class:`PairEstimate`
from the SVF cross-relation estimator (:mod:`~dualprobe.estimation.svf`, the default) or the
paper's difference method (:mod:`~dualprobe.estimation.difference`); :func:`relevelled`
searches a flow law's gas-level term again on the reconstructed gas;
:func:`dualprobe.estimation.compare.compare_methods` sets them side by side on simulated
data (not imported here: it needs the simulator).
"""

from __future__ import annotations

from dualprobe.estimation.pair import METHODS, characterise_pair, relevelled
from dualprobe.estimation.result import PairEstimate
from dualprobe.estimation.settings import GAP_THRESHOLD, discretisation_noise_std

__all__ = [
    "GAP_THRESHOLD",
    "METHODS",
    "PairEstimate",
    "characterise_pair",
    "discretisation_noise_std",
    "relevelled",
]
