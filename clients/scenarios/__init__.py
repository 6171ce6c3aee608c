"""Simulated scenarios shared by the tests, the benchmarks and the demo publisher."""

from clients.scenarios.multitarget import (
    ScenarioConfig,
    SensorSpec,
    SimulatedScan,
    crossing_scenario,
    reference_scenario,
    scale_scenario,
    simulate,
)

__all__ = [
    "ScenarioConfig",
    "SensorSpec",
    "SimulatedScan",
    "crossing_scenario",
    "reference_scenario",
    "scale_scenario",
    "simulate",
]
