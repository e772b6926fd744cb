"""Test scheduling for parallel runs.

``make test`` runs the suite on two pytest-xdist workers. Work units are handed to
whichever worker is free (it keeps at most a few tests queued). A long test that starts
last keeps one worker busy while the other idles, so the units go out longest first
(longest-processing-time-first scheduling keeps the workers' finishing times close):

* a test marked ``@pytest.mark.slow(seconds=S)`` is expected to take about S seconds on
  this project's 2-core reference machine (``slow`` without ``seconds``: 10 s); any
  other test is counted as :data:`DEFAULT_SECONDS`;
* the tests of a module in :data:`SHARED_FIXTURE_MODULES` form one unit, so its
  expensive module-scoped fixture is built once, on one worker; the unit's time is the
  sum of its tests'. Every other test is a unit of its own.

(xdist's own ``--dist loadgroup`` would do the grouping, but with pytest 9.2 it no longer
renames the tests it groups, so it groups nothing; :func:`pytest_xdist_make_scheduler`
hands xdist a scheduler with these units instead.) The order changes nothing else; every
test still runs, in one process as in two.
"""

from __future__ import annotations

from pathlib import PurePosixPath

import pytest

#: expected time (s) of a test without a ``slow`` marker
DEFAULT_SECONDS = 0.3
#: modules whose tests share a module-scoped fixture that runs simulations or installs
SHARED_FIXTURE_MODULES = frozenset({
    "test_capacity.py",  # width_drop_runs: ten road-world runs
    "test_install.py",  # installed: a non-editable pip install
    "test_config_cli.py",  # runs: cosim runs whose outputs the tests read
    "test_detector_agreement.py",  # agreement: a SUMO run with E1 detectors
    "test_gui.py",  # xvfb, shots: a display server and sumo-gui screenshots
})


def work_unit(nodeid: str) -> str:
    """The scheduling unit of a test: its module if the module shares a fixture, else
    the test itself."""
    module = nodeid.split("::", 1)[0]
    return module if PurePosixPath(module).name in SHARED_FIXTURE_MODULES else nodeid


def _seconds(item: pytest.Item) -> float:
    """The test's expected time (s) from its ``slow`` marker."""
    mark = item.get_closest_marker("slow")
    if mark is None:
        return DEFAULT_SECONDS
    return float(mark.kwargs.get("seconds", 10.0))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Order the units longest first (ties as collected), a unit's tests together."""
    total: dict[str, float] = {}
    first: dict[str, int] = {}
    for i, item in enumerate(items):
        unit = work_unit(item.nodeid)
        total[unit] = total.get(unit, 0.0) + _seconds(item)
        first.setdefault(unit, i)
    order = {id(item): i for i, item in enumerate(items)}
    items.sort(key=lambda it: (-total[work_unit(it.nodeid)], first[work_unit(it.nodeid)],
                               order[id(it)]))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """xdist's scope scheduler over :func:`work_unit`, in the collected order."""
    from xdist.scheduler import LoadScopeScheduling

    class UnitScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

    config.option.loadscopereorder = False  # keep the longest-first order
    return UnitScheduling(config, log)
