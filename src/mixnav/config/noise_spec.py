"""Noise processes from the tables of a scenario or dataset file.

The configuration side of :mod:`mixnav.noise.processes`: a TOML-like table
(``{"type": "mixture", "weights": [...], "sigmas": ["0.3 m", ...]}``) becomes
a process object, units parsed by :func:`mixnav.units.parse_quantity`, every
error a :class:`~mixnav.errors.ConfigError` naming the key path and file (an
:class:`~mixnav.errors.ArgumentError` of a process's constructor is re-raised
with its key).
"""

from __future__ import annotations

import difflib

from ..errors import ArgumentError, ConfigError
from ..noise.processes import (AR1, BiasSegments, Gaussian, GrossErrors, Mixture, NoiseProcess, Outages, Sum,
                               VarianceProfile, _is_white)
from ..units import DIMENSIONLESS, TIME, Dimension, UnitError, parse_quantity


# --------------------------------------------------------------------------
# config
# --------------------------------------------------------------------------
_KEYS = {
    "gaussian": {"sigma"},
    "mixture": {"weights", "sigmas", "means", "joint"},
    "gross": {"size", "every", "probability", "start", "sign", "channels"},
    "ar1": {"coefficient", "sigma", "innovation"},
    "bias_segments": {"segments"},
    "variance_profile": {"base", "steps", "drifts"},
    "sum": {"parts"},
    "outages": {"windows", "fraction", "channels"},
}
_ALIASES = {"normal": "gaussian", "gross_errors": "gross", "ar(1)": "ar1", "bias": "bias_segments",
            "multipath": "bias_segments", "profile": "variance_profile"}


def from_config(table: dict, dimension: Dimension, key_prefix: str = "noise",
                source: str | None = None):
    """Build a noise process from a TOML-like table.

    Parameters
    ----------
    table : dict
        ``type`` plus the keys of that type (values with units are text,
        e.g. ``"0.3 m"``; times such as segment bounds are text too,
        ``"10 s"``)::

            {type="gaussian", sigma="0.3 m"}            # or a list per channel
            {type="mixture", weights=[0.1, 0.9], sigmas=["0.3 m", "0.173 m"], means=["0 m", "0 m"]}
            {type="mixture", ..., joint=true}      # one component per epoch for all channels
            {type="gross", size="2.5 m", every=20, start=0, sign="random", channels=[0, 3]}
            {type="gross", size="2.5 m", probability=0.05}
            {type="ar1", coefficient=0.9, sigma="0.3 m"}          # sigma: innovation sd
            {type="ar1", coefficient=[[0.5, 0.1], [0.0, 0.7]], innovation={type="mixture", ...}}
            {type="bias_segments", segments=[["100 s", "160 s", "4 m"], {start="300 s", end="320 s", bias="-2 m"}]}
            {type="variance_profile", base={...}, steps=[["100 s", 3]], drifts=[["200 s", "400 s", 2]]}
            {type="sum", parts=[{...}, {...}]}
            {type="outages", windows=[["100 s", "130 s"]], fraction=0.1, channels=[2]}

        Aliases: normal, gross_errors, ar(1), bias, multipath, profile.
    dimension : mixnav.units.Dimension
        Dimension of the observable, e.g. ``LENGTH`` for pseudorange,
        ``VELOCITY`` for Doppler; sigmas, means, sizes and biases must have it.
    key_prefix : str
        Dotted path of ``table`` in the config file, used in error messages.
    source : str, optional
        The config file, used in error messages.

    Returns
    -------
    NoiseProcess or Outages

    Raises
    ------
    ConfigError
        Unknown type or key, missing key, missing or wrong unit, negative
        sigma, weights not summing to 1, non-stationary AR coefficient, ...;
        ``key`` is the full path, e.g. ``noise.parts[1].sigmas[0]``.
    """
    return _Builder(dimension, source).build(table, key_prefix)


class _Builder:
    def __init__(self, dim: Dimension, source):
        self.dim, self.source = dim, source

    def err(self, msg, key):
        return ConfigError(msg, file=self.source, key=key)

    def quantity(self, v, key, dim=None, nonnegative=False, positive=False):
        dim = self.dim if dim is None else dim
        try:
            x = parse_quantity(v, dim)
        except UnitError as exc:
            raise self.err(str(exc), key) from None
        if nonnegative and x < 0:
            raise self.err(f"must not be negative, got {v!r}", key)
        if positive and not x > 0:
            raise self.err(f"must be positive, got {v!r}", key)
        return x

    def quantities(self, v, key, dim=None, nonnegative=False, scalar_ok=True):
        if isinstance(v, (list, tuple)):
            if not v:
                raise self.err("must not be an empty list", key)
            return [self.quantity(x, f"{key}[{i}]", dim, nonnegative) for i, x in enumerate(v)]
        if not scalar_ok:
            raise self.err(f"expected a list, got {v!r}", key)
        return self.quantity(v, key, dim, nonnegative)

    def number_list(self, v, key):
        if isinstance(v, (list, tuple)):
            return [self.number_list(x, f"{key}[{i}]") for i, x in enumerate(v)]
        return self.quantity(v, key, DIMENSIONLESS)

    def table_list(self, v, key):
        if not isinstance(v, (list, tuple)):
            raise self.err(f"expected a list, got {v!r}", key)
        return v

    def record(self, item, key, names, dims):
        """(a, b, ...) from a list of len(names) or a table with those keys."""
        if isinstance(item, dict):
            self.check_keys(item, set(names), key)
            missing = [n for n in names if n not in item]
            if missing:
                raise self.err(f"missing key '{missing[0]}'", key)
            vals = [item[n] for n in names]
        elif isinstance(item, (list, tuple)) and len(item) == len(names):
            vals = list(item)
        else:
            raise self.err(f"expected [{', '.join(names)}] or a table with those keys, got {item!r}", key)
        out = []
        for n, v, d in zip(names, vals, dims):
            k = f"{key}.{n}"
            # only a bias may be a per-channel list
            out.append(self.quantities(v, k, d) if n == "bias" else self.quantity(v, k, d))
        return tuple(out)

    def check_keys(self, table, allowed, key):
        for k in table:
            if k not in allowed:
                close = difflib.get_close_matches(str(k), sorted(allowed), n=1)
                hint = f"; did you mean '{close[0]}'?" if close else f"; allowed: {', '.join(sorted(allowed))}"
                raise self.err(f"unknown key '{k}'{hint}", f"{key}.{k}" if key else str(k))

    def build(self, table, key):
        if not isinstance(table, dict):
            raise self.err(f"expected a table such as {{type=\"gaussian\", sigma=\"1 m\"}}, got {table!r}", key)
        if "type" not in table:
            raise self.err(f"missing key 'type' (one of {', '.join(_KEYS)})", key)
        typ = str(table["type"]).lower()
        typ = _ALIASES.get(typ, typ)
        if typ not in _KEYS:
            close = difflib.get_close_matches(typ, list(_KEYS) + list(_ALIASES), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise self.err(f"unknown noise type '{table['type']}' (one of {', '.join(_KEYS)}){hint}",
                           f"{key}.type")
        body = {k: v for k, v in table.items() if k != "type"}
        self.check_keys(body, _KEYS[typ], key)
        return getattr(self, "_" + typ)(body, key)

    def make(self, cls, key, *args, **kw):
        """Call a constructor; its errors name the argument, so prefix the key path."""
        try:
            return cls(*args, **kw)
        except ArgumentError as exc:
            raise self.err(exc.message, f"{key}.{exc.argument}" if exc.argument else key) from None

    def need(self, body, name, key):
        if name not in body:
            raise self.err(f"missing key '{name}'", f"{key}.{name}")
        return body[name]

    def _gaussian(self, b, key):
        return self.make(Gaussian, key, self.quantities(self.need(b, "sigma", key), f"{key}.sigma", nonnegative=True))

    def _mixture(self, b, key):
        w = self.need(b, "weights", key)
        if not isinstance(w, (list, tuple)) or not w:
            raise self.err(f"expected a list of weights, got {w!r}", f"{key}.weights")
        w = [self.quantity(x, f"{key}.weights[{i}]", DIMENSIONLESS, nonnegative=True) for i, x in enumerate(w)]
        s = self.quantities(self.need(b, "sigmas", key), f"{key}.sigmas", nonnegative=True, scalar_ok=False)
        m = self.quantities(b["means"], f"{key}.means") if "means" in b else 0.0
        joint = b.get("joint", False)
        if not isinstance(joint, bool):
            raise self.err(f"expected true or false, got {joint!r}", f"{key}.joint")
        return self.make(Mixture, key, w, s, m, joint)

    def _gross(self, b, key):
        kw = dict(size=self.quantity(self.need(b, "size", key), f"{key}.size", nonnegative=True))
        for name in ("every", "probability", "start", "sign", "channels"):
            if name in b:
                kw[name] = b[name]
        return self.make(GrossErrors, key, **kw)

    def _ar1(self, b, key):
        coef = self.number_list(self.need(b, "coefficient", key), f"{key}.coefficient")
        sigma = self.quantities(b["sigma"], f"{key}.sigma", nonnegative=True) if "sigma" in b else None
        inn = self.build(b["innovation"], f"{key}.innovation") if "innovation" in b else None
        if inn is not None and not _is_white(inn):
            raise self.err("innovation must be white: type gaussian, mixture, gross with probability, "
                           "or a sum of them",
                           f"{key}.innovation.type")
        return self.make(AR1, key, coef, sigma=sigma, innovation=inn)

    def _bias_segments(self, b, key):
        segs = self.table_list(self.need(b, "segments", key), f"{key}.segments")
        return self.make(BiasSegments, key, [self.record(s, f"{key}.segments[{i}]", ("start", "end", "bias"),
                                         (TIME, TIME, self.dim)) for i, s in enumerate(segs)])

    def _variance_profile(self, b, key):
        base = self.build(self.need(b, "base", key), f"{key}.base")
        if not isinstance(base, NoiseProcess):
            raise self.err("base must be an additive noise process (not outages)", f"{key}.base.type")
        steps = [self.record(s, f"{key}.steps[{i}]", ("at", "factor"), (TIME, DIMENSIONLESS))
                 for i, s in enumerate(self.table_list(b.get("steps", []), f"{key}.steps"))]
        drifts = [self.record(s, f"{key}.drifts[{i}]", ("start", "end", "factor"), (TIME, TIME, DIMENSIONLESS))
                  for i, s in enumerate(self.table_list(b.get("drifts", []), f"{key}.drifts"))]
        return self.make(VarianceProfile, key, base, steps, drifts)

    def _sum(self, b, key):
        parts = self.table_list(self.need(b, "parts", key), f"{key}.parts")
        built = [self.build(p, f"{key}.parts[{i}]") for i, p in enumerate(parts)]
        for i, p in enumerate(built):
            if not isinstance(p, NoiseProcess):
                raise self.err("outages are not additive noise; configure them separately",
                               f"{key}.parts[{i}].type")
        return self.make(Sum, key, *built)

    def _outages(self, b, key):
        wins = [self.record(w, f"{key}.windows[{i}]", ("start", "end"), (TIME, TIME))
                for i, w in enumerate(self.table_list(b.get("windows", []), f"{key}.windows"))]
        return self.make(Outages, key, wins, fraction=b.get("fraction"), channels=b.get("channels"))
