"""Scenarios: the TOML schema and its validation (``parse``), the built-in catalog (``catalog/*.toml``),
resource limits decided up front (``limits``), the resolved scenario every engine receives
(``resolved``), and each scenario's reference solution — closed form or DOP853 (``references``)."""
from cross_checks.scenario.parse import (
                                         REFERENCE_KINDS,
                                         SCENARIO_KINDS,
                                         Scenario,
                                         ScenarioError,
                                         catalog_names,
                                         catalog_path,
                                         load_scenario,
                                         long_run_names,
                                         parse_scenario,
)

__all__ = ["Scenario", "ScenarioError", "load_scenario", "parse_scenario", "catalog_names", "catalog_path",
           "REFERENCE_KINDS", "SCENARIO_KINDS", "long_run_names"]
