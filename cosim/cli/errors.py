"""The one place that turns user errors into a single ``error: ...`` line and an exit code."""

from __future__ import annotations

import sys
from collections.abc import Callable

from cosim.errors import CosimError


def run_command(func: Callable, ns, interrupted: str = "interrupted") -> int:
    """Call ``func(ns)``; a CosimError gives one stderr line and exit 2, Ctrl-C exit 130."""
    try:
        return func(ns)
    except CosimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"error: {interrupted}", file=sys.stderr)
        return 130
