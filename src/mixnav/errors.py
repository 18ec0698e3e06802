"""The errors mixnav raises at its public boundary.

Each names where the problem is (file and key, or file and line) and what is
wrong, so a user can fix their input without reading the code.
"""

from __future__ import annotations


class MixnavError(Exception):
    """Base class of every error mixnav raises on purpose."""


class ConfigError(MixnavError, ValueError):
    """A scenario or config value is missing, unknown or impossible.

    Parameters
    ----------
    message : str
        What is wrong and, where it helps, what would be right.
    file : str or None
        The config file, when the value came from one.
    key : str or None
        Dotted path of the offending key, e.g. ``imu.gyro_bias``.
    """

    def __init__(self, message: str, file: str | None = None, key: str | None = None):
        self.file = file
        self.key = key
        self.message = message
        where = ", ".join(p for p in (str(file) if file else None, f"key '{key}'" if key else None) if p)
        super().__init__(f"{where}: {message}" if where else message)


class ArgumentError(MixnavError, ValueError):
    """A library function or class got an impossible argument.

    Library code (filters, models, learners) names the *argument*; the config
    layer, which knows which file and key the value came from, maps it to a
    :class:`ConfigError` (``mixnav.config.errors.config_keys``).

    Parameters
    ----------
    message : str
        What is wrong and, where it helps, what would be right.
    argument : str or None
        The argument's name, dotted for a part of it (``mixtures.process.means``).
    """

    def __init__(self, message: str, argument: str | None = None):
        self.argument = argument
        self.message = message
        super().__init__(f"argument '{argument}': {message}" if argument else message)


class DataError(MixnavError, ValueError):
    """A data file is malformed: names the file and the line."""

    def __init__(self, message: str, file: str | None = None, line: int | None = None):
        self.file = file
        self.line = line
        self.message = message
        where = ", ".join(p for p in (str(file) if file else None, f"line {line}" if line else None) if p)
        super().__init__(f"{where}: {message}" if where else message)


class NumericalError(MixnavError, ArithmeticError):
    """A filter met numerical trouble it has no documented recovery for."""
