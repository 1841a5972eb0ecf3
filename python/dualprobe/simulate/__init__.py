"""Simulation of dual-sensor recordings: sensor models, gas temperature profiles, noise, ADC.

Everything here is exact up to rounding: gas temperature profiles are piecewise polynomials
(:mod:`~dualprobe.simulate.profiles`), sensors are integrated in closed form over every piece
(:mod:`~dualprobe.simulate.sensors`), and the Pt-100's resistance follows IEC 60751
(:mod:`~dualprobe.simulate.pt100`). ``from dualprobe import simulate as sim`` gives them all.
"""

from __future__ import annotations

from dualprobe.simulate.profiles import (
    GasProfile,
    constant_profile,
    fluctuating_profile,
    multistep_profile,
    step_profile,
)
from dualprobe.simulate.pt100 import pt100_resistance, pt100_temperature
from dualprobe.simulate.sensors import (
    PT100_1P5MM_FIRST,
    PT100_1P5MM_SECOND,
    PT100_1P5MM_TAU_COOL,
    PT100_1P5MM_TAU_HEAT,
    PT100_4P5MM_FIRST,
    PT100_4P5MM_SECOND,
    THERMOCOUPLE_20MS,
    THERMOCOUPLE_80MS,
    PairRecording,
    SensorModel,
    difference_equation_pair,
    simulate_hysteretic_sensor,
    simulate_pair,
    simulate_sensor,
)

__all__ = [
    "PT100_1P5MM_FIRST",
    "PT100_1P5MM_SECOND",
    "PT100_1P5MM_TAU_COOL",
    "PT100_1P5MM_TAU_HEAT",
    "PT100_4P5MM_FIRST",
    "PT100_4P5MM_SECOND",
    "THERMOCOUPLE_20MS",
    "THERMOCOUPLE_80MS",
    "GasProfile",
    "PairRecording",
    "SensorModel",
    "constant_profile",
    "difference_equation_pair",
    "fluctuating_profile",
    "multistep_profile",
    "pt100_resistance",
    "pt100_temperature",
    "simulate_hysteretic_sensor",
    "simulate_pair",
    "simulate_sensor",
    "step_profile",
]
