"""The ``cosim`` command line: run, list, config, plane, sweep, analyse.

Every user error (a bad scenario, option, network or output folder, SUMO failing)
prints one line ``error: ...`` on stderr and exits with status 2, with no traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

from cosim.analysis.cli import add_analyse_parser
from cosim.cli.errors import run_command
from cosim.cli.info import add_info_parsers
from cosim.cli.plane import add_plane_parser
from cosim.cli.run import add_run_parser
from cosim.errors import ConfigError
from cosim.sweeps.cli import add_sweep_parser

DESCRIPTION = """\
Lane-free CAV flocking co-simulated with SUMO.

  cosim run [NAME|FILE] [--set KEY=VALUE ...]   run a scenario (default: default)
  cosim list                                    built-in scenarios, sweeps, laws
  cosim config [NAME|FILE]                      a scenario with every default
  cosim plane NAME                              a seed reproduction (no SUMO)
  cosim sweep NAME|FILE                         a grid of runs in parallel
  cosim analyse DIR                             tables and figures of a sweep or run
"""


class OneLineParser(argparse.ArgumentParser):
    """argparse that reports a bad option as one ``error:`` line (exit 2)."""

    def error(self, message: str) -> None:  # noqa: D401 - argparse API
        print(f"error: {self.prog}: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    ap = OneLineParser(prog="cosim", description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    add_run_parser(sub)
    add_info_parsers(sub)
    add_plane_parser(sub)
    add_sweep_parser(sub)
    add_analyse_parser(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    try:
        ns = build_parser().parse_args(argv)
    except ConfigError as exc:  # an argparse type check (e.g. --duration nan)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        return run_command(ns.func, ns)
    except BrokenPipeError:  # `cosim list | head`: the reader left; not an error of ours
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
