"""``cosim ARGV`` in a forked child (:func:`sumo_cases.isolated.run_isolated`), with
everything it writes on file descriptors 1 and 2 captured, as a subprocess's pipes would
see it: Python's prints and the C++ messages of libsumo and SUMO alike."""

from __future__ import annotations

import os
import sys
import tempfile


def cosim_cli_output(argv: list[str], cwd: str) -> tuple[int, str, str]:
    """``cosim ARGV`` run in ``cwd`` (pass it to :func:`run_isolated`, never call it in
    the test process: it starts SUMO); returns its exit status, stdout and stderr."""
    from cosim.cli.main import main

    os.chdir(cwd)
    with tempfile.TemporaryFile("w+b") as out, tempfile.TemporaryFile("w+b") as err:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
        texts = []
        for fh in (out, err):
            fh.seek(0)
            texts.append(fh.read().decode(errors="replace"))
    return int(code or 0), texts[0], texts[1]
