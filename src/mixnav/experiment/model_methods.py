"""Methods on a motion model other than the strapdown INS: the estimator a method entry
names, and every method run through one :class:`~mixnav.engine.Engine` each (plus the RTS
smoother on request). Shared by the odometry + pseudorange datasets
(:mod:`mixnav.experiment.vehicle_process`: dead reckoning) and the raw-GNSS datasets
(:mod:`mixnav.experiment.spp_process`: constant velocity).

A method entry is anything with ``name``, ``estimator``, ``robust``, ``mixture``,
``options`` and ``smooth`` (:class:`mixnav.config.vehicle_schema.VehicleMethod` and its
raw-GNSS subclass).
"""

from __future__ import annotations

from ..config.errors import config_keys
from ..engine.engine import Engine
from ..engine.result import FilterResult
from ..engine.smoother import rts_smooth
from ..errors import ConfigError

__all__ = ["make_estimator", "run_methods"]


def make_estimator(method, source: str, index: int, seed: int = 0, model_name: str = "this motion model",
                   mixture_start: dict | None = None):
    """The estimator of a method (any motion model): ekf, robust-adaptive, gaussian-mixture
    (given mixtures, or learned online), epoch-mixture, sage-husa, vb-akf; options named in
    errors by their file key (``methods[index]...``). ``mixture_start``: the LOS/NLOS
    mixture a track alignment learned (:func:`mixnav.experiment.vehicle_process.mixture_handover`),
    the epoch mixture's starting values unless the method's options set them."""
    key = f"methods[{index}]"
    name = method.estimator
    opts = dict(method.options or {})
    _check_options(name, opts, source, f"{key}.options")
    with config_keys(f"{key}.options", source):
        if name == "ekf":
            from ..filters.ekf import KalmanEstimator
            return KalmanEstimator(**opts)
        if name == "robust-adaptive":
            from ..config.schema import RobustConfig
            from ..filters.robust import RobustEstimator
            rc = method.robust or RobustConfig()
            return RobustEstimator(rc.k0, rc.k1, rc.c, **opts)
        if name == "gaussian-mixture":
            from ..config.schema import MixtureConfig
            from ..filters.gmekf import BankEstimator
            from .methods import _bank_parts
            mc = method.mixture or MixtureConfig()
            if mc.colored is not None:
                raise ConfigError("the coloured-noise bank (M6) differences measurements of an INS layout; not "
                                  f"available on {model_name}", file=source, key=f"{key}.mixture.colored")
            mixtures, online, _, _ = _bank_parts(mc, None, seed, method.name, source, f"{key}.mixture")
            return BankEstimator(mixtures, max_components=mc.max_components, online=online, gate=mc.gate,
                                 outlier_mean=mc.outlier_mean, divergence_window=mc.divergence_window,
                                 divergence_nis=mc.divergence_nis)
        if name == "epoch-mixture":
            from ..filters.epoch_mixture import EpochMixtureEstimator
            start = dict(mixture_start or {})
            if list(opts.get("cn0_edges", [])) != start.pop("cn0_edges", None):
                start.pop("los_weight_bands", None)      # learned on other bands
            return EpochMixtureEstimator(**{**start, **opts})
        if name == "sage-husa":
            from ..filters.sage_husa import SageHusaEstimator
            return SageHusaEstimator(**opts)
        if name == "vb-akf":
            from ..filters.vb import ChannelNoise, VbKalmanEstimator
            return VbKalmanEstimator(ChannelNoise(**opts))
    raise KeyError(name)   # unreachable: the schemas admit only these


def _option_target(name: str):
    """The callable a method's ``options`` are keyword arguments of (None: no options taken)."""
    if name == "ekf":
        from ..filters.ekf import KalmanEstimator
        return KalmanEstimator
    if name == "robust-adaptive":
        from ..filters.robust import RobustEstimator
        return RobustEstimator
    if name == "epoch-mixture":
        from ..filters.epoch_mixture import EpochMixtureEstimator
        return EpochMixtureEstimator
    if name == "sage-husa":
        from ..filters.sage_husa import SageHusaEstimator
        return SageHusaEstimator
    if name == "vb-akf":
        from ..filters.vb import ChannelNoise
        return ChannelNoise
    return None


def _check_options(name: str, opts: dict, source: str, key: str) -> None:
    """An option the estimator does not take is a config error naming it (not a TypeError)."""
    import inspect
    if not opts:
        return
    target = _option_target(name)
    params = {} if target is None else inspect.signature(target).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    fixed = {"k0", "k1", "c"} if name == "robust-adaptive" else set()   # from the [robust] table
    known = [p for p, v in params.items() if p != "self" and p not in fixed
             and v.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)]
    tables = {"gaussian-mixture": "; its settings are the method's [mixture] table",
              "robust-adaptive": "; k0, k1 and c are the method's [robust] table"}
    for k in opts:
        if k not in known:
            raise ConfigError(f"unknown option of estimator '{name}' (it takes: {', '.join(known) or 'none'}"
                              f"{tables.get(name, '')})", file=source, key=f"{key}.{k}")


def run_methods(methods, make_motion, models, inputs, init, output_times, source: str, seed: int = 0,
                model_name: str = "this motion model", mixture_start: dict | None = None) -> dict[str, FilterResult]:
    """Run each ``(index, method)`` of ``methods``: a fresh motion model from ``make_motion()``,
    the method's estimator, the measurement ``models``, driven by ``inputs`` from ``init``,
    solutions at ``output_times``; ``method.smooth`` adds ``<name>-smoothed`` (RTS). The
    engine's random stream is ``seed`` for every method (the estimators that draw, draw
    from their own). ``mixture_start``: as :func:`make_estimator`."""
    results: dict[str, FilterResult] = {}
    for k, method in methods:
        est = make_estimator(method, source, k, seed, model_name, mixture_start)
        res = Engine(make_motion(), est, list(models), covariance_interval=1.0, rng=seed,
                     history=method.smooth).run(inputs, init, output_times=output_times)
        results[method.name] = res
        if method.smooth:
            results[f"{method.name}-smoothed"] = rts_smooth(res)
    return results
