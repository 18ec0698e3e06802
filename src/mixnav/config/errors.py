"""Errors of library objects, said in the words of a config file.

Library code names the *argument* that is wrong (:class:`~mixnav.errors.ArgumentError`);
the config layer knows which file and key the value came from.
"""

from __future__ import annotations

from contextlib import contextmanager

from ..errors import ArgumentError, ConfigError


@contextmanager
def config_keys(prefix: str, file: str | None = None, rename: dict | None = None):
    """Turn an :class:`ArgumentError` raised inside into a :class:`ConfigError`.

    Parameters
    ----------
    prefix : str
        Dotted key of the config table the arguments come from (``methods[2]``).
    file : str, optional
        The config file.
    rename : dict, optional
        Argument name (or its first dotted part) -> key relative to ``prefix``
        where the two differ (``{"psi": "mixture.colored.measurement"}``).
    """
    try:
        yield
    except ArgumentError as exc:
        arg = exc.argument or ""
        head, dot, rest = arg.partition(".")
        rename = rename or {}
        if arg in rename:
            key = rename[arg]
        elif head in rename:
            key = rename[head] + dot + rest
        else:
            key = arg
        key = f"{prefix}.{key}" if key else prefix
        raise ConfigError(exc.message, file=file, key=key) from None
