"""Errors that the command line turns into one clear line and a non-zero exit."""


class CosimError(Exception):
    """Base class: a problem the user can fix; printed as one line, no traceback."""


class ConfigError(CosimError):
    """Invalid scenario or sweep configuration (unknown key, wrong type, bad value)."""


class NetworkError(CosimError):
    """A network file is missing or broken, or netconvert failed."""


class SumoStartError(CosimError):
    """SUMO (libsumo) failed to start or crashed."""
