"""``cosim plane NAME``: a seed reproduction in the SUMO-free plane world."""

from __future__ import annotations

from pathlib import Path

from cosim.cli.run import check_out_option, positive_float
from cosim.errors import CosimError


def cmd_plane(ns) -> int:
    from cosim.output_dir import check_output_dir, prepare_output_dir
    from cosim.plane.scenarios import SCENARIOS, run_plane_scenario

    if ns.name not in SCENARIOS:
        raise CosimError(f"unknown plane scenario {ns.name!r}; choose from "
                         f"{', '.join(sorted(SCENARIOS))}")
    kwargs = {}
    if ns.saturation is not None:
        if ns.name != "seed001":
            raise CosimError("--saturation applies to seed001 only")
        kwargs["speed_limit_mps"] = ns.saturation
    if ns.seed is not None and not 0 <= ns.seed < 2**32:
        raise CosimError(f"--seed must be in [0, 2^32), got {ns.seed}")
    check_out_option(ns.out)
    out = Path(ns.out or Path("outputs") / f"plane_{ns.name}")
    check_output_dir(out, replace=ns.replace, what="plane output folder")
    res = run_plane_scenario(ns.name, seed=ns.seed, duration_s=ns.duration, **kwargs)
    prepare_output_dir(out, replace=ns.replace, what="plane output folder")
    res.write(out)
    m = res.metrics
    print(m.iloc[[0, len(m) // 2, -1]].T.to_string())
    if ns.plot:
        from cosim.plane.plots import plot_plane_result

        for p in plot_plane_result(res, out):
            print(f"figure: {p}")
    print(f"outputs written to {out}/")
    return 0


def add_plane_parser(sub) -> None:
    from cosim.plane.scenarios import DESCRIPTIONS

    names = "; ".join(f"{k}: {v}" for k, v in DESCRIPTIONS.items())
    pl = sub.add_parser("plane", help="run a seed reproduction in the SUMO-free plane world",
                        description=f"Run a seed reproduction. Names: {names}.")
    pl.add_argument("name", help=f"one of {', '.join(DESCRIPTIONS)}")
    pl.add_argument("--seed", type=int, help="random seed of the initial state")
    pl.add_argument("--duration", type=positive_float, help="simulated time, s")
    pl.add_argument("--saturation", type=positive_float,
                    help="seed001 only: speed limit sat(p, p_max), m/s")
    pl.add_argument("--out", help="output folder (default outputs/plane_NAME)")
    pl.add_argument("--replace", action="store_true", help="clear a non-empty --out first")
    pl.add_argument("--plot", action="store_true",
                    help="write PNG figures: paths with the obstacle and road edges, distances")
    pl.set_defaults(func=cmd_plane)
