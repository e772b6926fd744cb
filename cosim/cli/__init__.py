"""The ``cosim`` command line: ``run``, ``list``, ``config``, ``plane``, ``sweep`` and
``analyse``; :mod:`~cosim.cli.errors` turns every bad input into one ``error:`` line
and exit status 2."""
