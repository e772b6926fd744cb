"""``cosim list`` (everything built in, with descriptions) and ``cosim config`` (a resolved
scenario with every default)."""

from __future__ import annotations

from cosim.config.builtins import builtin_scenarios, builtin_sweeps, description


def cmd_list(ns) -> int:
    from controllers import registry
    from cosim.plane.scenarios import DESCRIPTIONS

    print("built-in scenarios (cosim run NAME):")
    for name, path in builtin_scenarios().items():
        print(f"  {name:<22} {description(path, 'scenario')}")
    print("\nbuilt-in sweeps (cosim sweep NAME):")
    for name, path in builtin_sweeps().items():
        print(f"  {name:<22} {description(path, 'sweep')}")
    print("\nplane-world seed reproductions (cosim plane NAME):")
    for name, text in DESCRIPTIONS.items():
        print(f"  {name:<22} {text}")
    print("\nCAV laws (controller.kind; or a class of yours as module.path:ClassName):")
    for kind in registry.kinds():
        print(f"  {kind:<22} {registry.entry(kind).description}")
    return 0


def cmd_config(ns) -> int:
    from cosim.cli.run import run_overrides
    from cosim.config.scenario import load_scenario
    from cosim.config.toml_write import dumps_toml

    sc = load_scenario(ns.scenario, run_overrides(ns))
    print(f"# {ns.scenario or 'default'}: the resolved scenario, every key with its value")
    print(dumps_toml(sc.to_dict()), end="")
    return 0


def add_info_parsers(sub) -> None:
    ls = sub.add_parser("list", help="list built-in scenarios, sweeps, plane reproductions, laws",
                        description="List everything built in, each with its description.")
    ls.set_defaults(func=cmd_list)
    c = sub.add_parser("config", help="print a scenario fully resolved (every default)",
                       description="Print the resolved scenario as TOML: every key of every "
                                   "section with the value a run would use.")
    c.add_argument("scenario", nargs="?", help="a scenario TOML file or a built-in name")
    c.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a key first, as for cosim run")
    c.set_defaults(func=cmd_config)
