"""Simulation of dual-sensor recordings: sensor models, gas temperature profiles, noise, ADC.

Everything here is exact up to rounding: gas temperature profiles are piecewise polynomials
(:mod:`~dualprobe.simulate.profiles`), sensors are integrated in closed form over every piece
(:mod:`~dualprobe.simulate.sensors`), and the Pt-100's resistance follows IEC 60751
(:mod:`~dualprobe.simulate.pt100`). Field conditions (a vehicle drive cycle, sensors whose time
constants follow the gas flow, sheaths, logger effects) are in
:mod:`~dualprobe.simulate.drive_cycle`. ``from dualprobe import simulate as sim`` gives them all.
"""

from __future__ import annotations

from dualprobe.simulate.drive_cycle import (
    DriveCycle,
    FieldRecording,
    FieldSensor,
    drive_cycle,
    simulate_field_pair,
)
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
    "DriveCycle",
    "FieldRecording",
    "FieldSensor",
    "GasProfile",
    "PairRecording",
    "SensorModel",
    "constant_profile",
    "difference_equation_pair",
    "drive_cycle",
    "fluctuating_profile",
    "multistep_profile",
    "pt100_resistance",
    "pt100_temperature",
    "simulate_field_pair",
    "simulate_hysteretic_sensor",
    "simulate_pair",
    "simulate_sensor",
    "step_profile",
]
