"""The one error a controller raises for a bad parameter (:class:`ParameterError`).

Config validation (:mod:`cosim.config`) turns it into one ``error:`` line naming the key.
"""


class ParameterError(ValueError):
    """An invalid controller parameter; the message names it."""
