"""The README's corridor figures: a top view of the weaving section and the N-curves.

Usage::

    python -m experiments.corridor_figure [--share 0.7] [--seed 1] [--out docs/figures]

Runs the built-in ``corridor`` scenario (its OD demand of 6 000 veh/h) for 300 s with
trajectories, then draws ``corridor_top_view.png`` (the stretch from the acceleration
strip's end to the gore, 1 400-2 560 m, at three times: CAVs blue, human drivers orange)
and ``corridor_n_curves.png`` (cumulative counts at the merge and the off-ramp,
:func:`cosim.analysis.figures.runs.n_curves_figure`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from cosim.cli.errors import run_command
from cosim.errors import ConfigError

DURATION_S = 300.0
TIMES_S = (200.0, 240.0, 280.0)
WINDOW_M = (1400.0, 2560.0)


def make(share: float, seed: int, out: Path) -> list[Path]:
    from cosim.analysis.figures.output import save
    from cosim.analysis.figures.runs import n_curves_figure, road_geometry, top_view_figure
    from cosim.config import load_scenario
    from cosim.config.schema import plain
    from cosim.sim.runner import run_scenario

    sc = load_scenario("corridor", {"demand.cav_share": share, "scenario.seed": seed,
                                    "scenario.duration_s": DURATION_S,
                                    "outputs.trajectories": True})
    with tempfile.TemporaryDirectory() as tmp:
        res = run_scenario(sc, out_dir=Path(tmp) / "run")
        edges, lanes, _ = road_geometry(plain(sc.network))
        name = f"corridor, {share:.0%} CAVs, seed {seed}"
        return [
            save(top_view_figure(res.trajectories, times=TIMES_S, s_range=WINDOW_M,
                                 edges=edges, lane_lines=lanes,
                                 title=f"Weaving section to the gore: {name}"),
                 out / "corridor_top_view.png"),
            save(n_curves_figure(res.trips, title=f"N-curves: {name}"),
                 out / "corridor_n_curves.png"),
        ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments.corridor_figure",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--share", type=float, default=0.7, help="CAV share, 0..1 (default 0.7)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="docs/figures", help="folder (default docs/figures)")

    def cmd(ns: argparse.Namespace) -> int:
        if not 0.0 <= ns.share <= 1.0:
            raise ConfigError(f"--share must be in [0, 1] (got {ns.share:g})")
        for f in make(ns.share, ns.seed, Path(ns.out)):
            print(f"figure: {f}")
        return 0

    return run_command(cmd, ap.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
