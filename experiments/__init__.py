"""Built-in experiments: scenario files, sweep files and the seed reproduction scripts.

Installed as package data (``importlib.resources``), so ``cosim run NAME`` and
``cosim sweep NAME`` work from any folder after ``pip install .``.

    scenarios/*.toml   built-in scenarios (``cosim run NAME``)
    sweeps/*.toml      built-in sweeps (``cosim sweep NAME``)
    seed00*.py         seed reproductions (``python -m experiments.seed001_delays``)
"""
