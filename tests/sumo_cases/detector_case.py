"""``experiments/check_detectors.py --quick --json --out OUT`` in this process, for
tests/test_detector_agreement.py, which calls it in a process of its own
(:func:`sumo_cases.isolated.run_isolated`; it starts SUMO).

The script's ``main`` runs as on the command line (arguments, the run, the comparison,
the tables and the ``RESULT <json>`` line, read back here), except that its
``run_case`` runs the scenario here instead of in a fresh interpreter: the same child
code (``check_detectors._CHILD``, with the same ``sys.argv``), in this process, which
holds no other simulation.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path


def check_detectors_quick(out: str) -> dict:
    """The ``RESULT`` of ``check_detectors.py --quick --json --out OUT`` (its exit status
    must be 0)."""
    from experiments import check_detectors as cd

    def run_case_here(spec: dict, out_dir: Path, env: dict | None = None,
                      timeout: float = 600.0) -> Path:
        argv = sys.argv
        sys.argv = ["-c", str(out_dir), json.dumps(spec)]
        try:
            code = compile(cd._CHILD.format(root=str(cd.ROOT)), "<check_detectors child>",
                           "exec")
            exec(code, {"__name__": "__main__"})
        finally:
            sys.argv = argv
        return Path(out_dir)

    cd.run_case = run_case_here
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        status = cd.main(["--quick", "--json", "--out", out])
    assert status == 0, f"check_detectors.main returned {status}:\n{text.getvalue()[-3000:]}"
    lines = [ln for ln in text.getvalue().splitlines() if ln.startswith("RESULT ")]
    assert lines, f"no RESULT line from check_detectors:\n{text.getvalue()[-2000:]}"
    return json.loads(lines[-1][len("RESULT "):])
