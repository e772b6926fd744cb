"""Scenario configuration: frozen sections loaded from TOML, validated on load.

    schema.py     typed construction of dataclasses from TOML tables (finite numbers,
                  unknown keys, one-line errors)
    sections.py   the sections the co-simulation owns ([scenario], [controller],
                  [obstacle], [outputs])
    scenario.py   Scenario: all sections; loading files, built-in names, overrides
    checks.py     checks across sections (geometry, vehicle sizes, time)
    overrides.py  dotted-key overrides (``--set demand.cav_share=0.5``)
    builtins.py   the built-in scenario and sweep files (package data)
    toml_write.py writing a resolved scenario back as TOML
"""

from cosim.config.scenario import (
    SECTIONS,
    Scenario,
    check_parameter_path,
    default_scenario,
    load_scenario,
    scenario_from_dict,
)

__all__ = [
    "SECTIONS",
    "Scenario",
    "check_parameter_path",
    "default_scenario",
    "load_scenario",
    "scenario_from_dict",
]
