"""Building filters and measurement models from a method of a scenario or dataset file.

The configuration stops here: below this module every object takes plain,
validated Python arguments and names the *argument* that is wrong
(:class:`mixnav.errors.ArgumentError`); :func:`build` maps those to the
config file's keys (:func:`mixnav.config.errors.config_keys`). Estimators are
found by name in the registry (:mod:`mixnav.filters.registry`), which builds them from
their options: the method's ``[methods.options]``, or its own table (``[robust]``;
the ``[mixture]`` and ``[imm]`` tables are turned into objects here). One builder
serves every motion model: :func:`build` (the strapdown INS: a filter) and
:func:`estimator_for` (any other: an estimator for the engine).
"""

from __future__ import annotations

import numpy as np

from ..config.errors import config_keys
from ..config.loader import imu_model
from ..config.method_schema import EmBiasConfig, MethodConfig, MixtureConfig, RobustConfig
from ..errors import ConfigError
from ..filters.registry import METHOD_TYPES, BuildContext, check_motion
from ..ins.error_model import ClockModel
from ..ins.imu_model import ImuErrorModel
from ..measurements.loose import LooseGnss

#: Method type -> one-line description (listed by ``mixnav scenarios``).
METHODS = {k: "M1 closed-loop error-state EKF, " + v for k, v in METHOD_TYPES.items()}



def __getattr__(name):
    # ESTIMATORS (registered name -> description) imports every estimator: built when asked
    if name == "ESTIMATORS":
        from ..filters.registry import estimator_names, estimator_spec
        return {n: estimator_spec(n).description for n in estimator_names()}
    raise AttributeError(name)


def _options(method) -> dict:
    """The settings the registry builds the method's estimator from: its ``[robust]`` table
    (robust-adaptive) under its ``[methods.options]``."""
    table = method.robust.model_dump() if getattr(method, "robust", None) is not None else {}
    return {**table, **dict(method.options or {})}


def estimator_for(method, source, index: int, seed: int = 0, motion: str | None = None, training=None,
                  mixture_start: dict | None = None, motion_model=None):
    """The estimator of ``method`` (any entry with ``name``, ``estimator``, ``robust``,
    ``mixture``, ``options``) for a run on the named ``motion`` model, built by the registry;
    errors under the method's keys; ``motion_model``: the run's motion model object. The
    strapdown INS's filters come from :func:`build`."""
    key = f"methods[{index}]"
    with config_keys(key, source):
        spec = check_motion(method.estimator, motion) if motion else check_motion(method.estimator, "strapdown")
    context = BuildContext(motion=motion_model, method=method, training=training, seed=seed, source=source, index=index,
                           extra={"mixture_start": mixture_start})
    if spec.table == "mixture":
        mc = method.mixture or MixtureConfig()
        if mc.colored is not None:
            raise ConfigError("the coloured-noise bank (M6) differences measurements of an INS layout; not "
                              f"available on the {motion} model", file=source, key=f"{key}.mixture.colored")
        mixtures, online, _, _ = _bank_parts(mc, training, seed, method.name, source, f"{key}.mixture")
        context.extra["bank"] = dict(mixtures=mixtures, max_components=mc.max_components, online=online,
                                     gate=mc.gate, outlier_mean=mc.outlier_mean,
                                     divergence_window=mc.divergence_window, divergence_nis=mc.divergence_nis)
    with config_keys(f"{key}.options", source):
        return spec.make(_options(method), context=context)

#: Arguments of the built-in estimators -> the method's keys where they differ.
_RENAME = {"k0": "robust.k0", "k1": "robust.k1", "c": "robust.c", "max_components": "mixture.max_components",
           "psi": "mixture.colored.measurement", "psi_channels": "mixture.colored.channels",
           "psi_process": "mixture.colored.process", "psi_measurement": "mixture.colored.measurement",
           "process_interval": "mixture.colored.process_interval", "kinds": "mixture.learn.observables",
           "mixtures": "mixture", "observables": "mixture.learn.observables", "process": "mixture.process",
           "prior": "mixture.prior", "window": "mixture.learn.online.window",
           "every": "mixture.learn.online.every", "gate": "mixture.learn.online.gate", "layout": "states"}


def build(method: MethodConfig, default_imu: ImuErrorModel, fixes, lever_arm, source=None, index: int = 0,
          observations=None, clock: ClockModel | None = None, training: dict | None = None, seed: int = 0,
          aiding=None):
    """The filter and its measurement models for one method of a config.

    The filter models the IMU with the method's own ``imu_grade``/``imu_errors``
    when given, otherwise with ``default_imu`` (the simulated IMU of a
    scenario, or the dataset's IMU model). Tight methods need the raw
    ``observations`` (:class:`mixnav.gnss.observables.GnssObservations`) and
    the receiver ``clock`` model. A Gaussian-mixture method that learns its
    mixtures needs ``training`` residuals (:func:`mixnav.sim.training.training_residuals`).
    A method with land-vehicle ``aiding`` needs the run's
    :class:`~mixnav.experiment.aiding.AidingInputs`.
    """
    with config_keys(f"methods[{index}]", source, _RENAME):
        filt, meas = _build(method, default_imu, fixes, lever_arm, source, index, observations, clock, training,
                            seed, aiding)
    if method.smooth and not getattr(filt, "can_smooth", False):
        raise ConfigError(f"estimator '{method.estimator}' cannot be smoothed (the RTS smoother needs one "
                          "Gaussian belief per event; a bank of components has none)", file=source,
                          key=f"methods[{index}].smooth")
    return filt, meas


def run_method(method: MethodConfig, filt, imu, init, meas, source=None, index: int = 0, taken=(),
               **kwargs) -> dict:
    """Run one method's filter; with ``smooth = true`` also its RTS smoother.

    Returns ``{name: FilterResult}``: the causal result under the method's name and,
    when smoothed, ``"<name>-smoothed"`` (:func:`mixnav.engine.smoother.rts_smooth`),
    with its own covariance, so metrics, tables and figures treat it as a method.
    ``taken``: the names of the file's methods (a smoothed name may not clash).
    """
    res = filt.run(imu, init, meas, history=method.smooth, **kwargs)
    if not method.smooth:
        return {method.name: res}
    from ..engine.smoother import rts_smooth
    name = f"{method.name}-smoothed"
    if name in taken:
        raise ConfigError(f"method '{method.name}' is smoothed into '{name}', which another method is named",
                          file=source, key=f"methods[{index}].smooth")
    smoothed = rts_smooth(res)
    res.history = None  # the backward pass is done: do not keep 3 n^2 doubles per event
    return {method.name: res, name: smoothed}


def _build(method, default_imu, fixes, lever_arm, source, index, observations, clock, training, seed, aiding):
    from .aiding import aiding_models, method_layout
    layout = method_layout(method, aiding, source, index)
    if method.type in ("tight-ekf", "tdcp-ekf") and observations is not None:   # an offset per further system
        from ..measurements.tight import observation_systems, tight_layout
        layout = tight_layout(layout, observation_systems(observations))
    aids = aiding_models(method, layout, aiding, source, index)
    model = default_imu
    if method.imu_grade is not None or method.imu_errors is not None:
        model = imu_model(method.imu_grade, method.imu_errors or {}, source,
                          f"methods[{index}].imu_errors", f"methods[{index}].imu_grade")
    if method.type == "loose-ekf":
        meas = [LooseGnss(fixes, lever_arm, layout)]
        clock = None
    elif method.type in ("tight-ekf", "tdcp-ekf"):
        if observations is None:
            raise ConfigError(f"method '{method.name}' is tightly coupled but there are no raw "
                              "GNSS observations", file=source, key=f"methods[{index}].type")
        clock = clock or ClockModel()
        from ..measurements.tdcp import TdcpGnss
        from ..measurements.tight import TightGnss
        if method.type == "tdcp-ekf":
            meas = [TdcpGnss(observations, lever_arm, layout, clone=method.tdcp_previous == "clone")]
        else:
            meas = [TightGnss(observations, lever_arm, layout, use_range_rate=method.use_range_rate)]
    else:
        raise KeyError(method.type)  # unreachable: the schema admits only known types
    meas = meas + aids
    common = dict(covariance_interval=method.covariance_interval, clock=clock)
    if method.estimator == "imm":
        return _imm(method, layout, model, meas[0], aids, source, index, common, training, seed), meas
    if method.estimator == "gaussian-mixture":
        from ..filters.gmekf import GaussianMixtureEkf
        mc = method.mixture or MixtureConfig()
        if mc.colored is not None:
            return _colored(method, mc, layout, model, meas, training, source, index, common, seed)
        mixtures, online, learning_time, failed = _bank_parts(mc, training, seed, method.name, source,
                                                              f"methods[{index}].mixture")
        return GaussianMixtureEkf(layout, model, mixtures, max_components=mc.max_components,
                                  learning_time_s=learning_time, online=online, learner_not_converged=failed,
                                  gate=mc.gate, outlier_mean=mc.outlier_mean, divergence_window=mc.divergence_window,
                                  divergence_nis=mc.divergence_nis, **common), meas
    from ..filters.facade import Filter
    with config_keys(f"methods[{index}].options", source):
        return Filter(method.estimator, layout, model, _options(method), **common,
                      context=BuildContext(method=method, training=training, seed=seed, source=source,
                                           index=index)), meas


def _bank_parts(mc: MixtureConfig, training, seed: int, name: str, source, key: str):
    """A ``[mixture]`` table's bank: ``(mixtures, online settings or None, learning time [s],
    fits not converged)``, the mixtures given or learned offline from ``training``."""
    from ..noise.learn.online import OnlineSettings
    online = None
    if mc.learn is not None and mc.learn.online is not None:
        oc = mc.learn.online
        online = OnlineSettings(tuple(mc.learn.observables), window=oc.window, every=oc.every, gate=oc.gate,
                                n_components=mc.learn.n_components, prune=mc.learn.prune)
    if mc.learn is not None and mc.learn.offline:
        if training is None:
            raise ConfigError(f"'{name}' learns its mixtures from a training stretch, which only simulated "
                              "scenarios provide", file=source, key=f"{key}.learn")
        learned = _learn(mc, training, seed)
        return learned.mixtures, online, learned.learning_time_s, learned.not_converged
    return mixtures_from_config(mc), online, 0.0, 0


def _imm(method, layout, model, gnss, aids, source, index, common, training=None, seed=0):
    """M9: the IMM of the method's modes, each updated by the measurements it lists."""
    from ..filters.ekf import KalmanEstimator
    from ..filters.imm import ImmEkf
    from ..filters.em_bias import EmBiasKalman, EmBiasSettings
    from ..filters.gmekf import BankEstimator
    from ..filters.robust_adaptive import RobustEstimator
    ic = method.imm
    by_name = {"gnss": gnss, **dict(zip(method.aiding, aids))}
    sets = [[by_name[x] for x in mode.measurements] for mode in ic.modes]
    makers = []
    for k, mode in enumerate(ic.modes):
        if mode.estimator == "robust-adaptive":
            rc = mode.robust or RobustConfig()
            makers.append(lambda rc=rc: RobustEstimator(rc.k0, rc.k1, rc.c, carry_mean=True))
        elif mode.estimator == "em-bias":
            ec = mode.em or EmBiasConfig()
            st = EmBiasSettings(window=float(ec.window), min_samples=ec.min_samples,
                                min_separation=float(ec.min_separation), min_weight=ec.min_weight,
                                min_separation_sigmas=ec.min_separation_sigmas,
                                max_state_sigma=None if ec.max_state_sigma is None else float(ec.max_state_sigma),
                                gate=ec.gate, refit_every=ec.refit_every)
            makers.append(lambda st=st: EmBiasKalman({gnss}, st, carry_mean=True))
        elif mode.estimator == "gaussian-mixture":
            mc = mode.mixture or MixtureConfig()
            mixtures, online, _, _ = _bank_parts(mc, training, seed, f"mode '{mode.name}' of '{method.name}'",
                                                 source, f"methods[{index}].imm.modes[{k}].mixture")
            makers.append(lambda mixtures=mixtures, mc=mc, online=online: BankEstimator(
                mixtures, mc.max_components, online=online, carry_mean=True, gate=mc.gate,
                outlier_mean=mc.outlier_mean, divergence_window=mc.divergence_window,
                divergence_nis=mc.divergence_nis))
        elif mode.estimator == "ekf":
            makers.append(lambda: KalmanEstimator(carry_mean=True))
        else:   # registered as a mode, but its mean-carrying child is not built here yet
            raise ConfigError(f"estimator '{mode.estimator}' cannot yet be built as an IMM mode (these can: "
                              "ekf, robust-adaptive, em-bias, gaussian-mixture)", file=source,
                              key=f"methods[{index}].imm.modes[{k}].estimator")
    interval = None if ic.transition_interval == "epoch" else float(ic.transition_interval)
    with config_keys(f"methods[{index}].imm", source):
        return ImmEkf(layout, model, sets, ic.transition, ic.initial_probabilities, interval,
                      [m.name for m in ic.modes], makers, output=ic.output, **common)


def _colored(method, mc, layout, model, meas, training, source, index, common, seed):
    """M6: the coloured-noise mixture EKF and its differenced measurement models.

    Coefficients given as ``"fit"`` are fitted to the training series; learned
    mixtures are learned from the training series *whitened* with the
    coefficients (``e_k - psi e_{k-1}``, the driving noise of P2 eqs. 6-7).
    """
    import time
    from ..measurements.differenced import DifferencedMeasurement
    from ..noise.ar import whiten_ar1
    from ..filters.colored import ColoredMixtureEkf, fit_coefficient
    cc = mc.colored
    key = f"methods[{index}].mixture.colored"
    if mc.learn is not None and mc.learn.online is not None:
        raise ConfigError("online re-learning of the mixtures is not available with the coloured-noise "
                          "mixture EKF (M6)", file=source, key=f"methods[{index}].mixture.learn.online")
    if method.type == "tdcp-ekf":
        raise ConfigError("the coloured-noise mixture EKF differences pseudoranges and range rates; TDCP "
                          "already differences the carrier: use type = \"tight-ekf\"", file=source,
                          key=f"methods[{index}].type")
    series = (training or {}).get("series", {})

    def coefficient(v, kind, k):
        if v != "fit":
            return float(v)
        if kind not in series:
            raise ConfigError("'fit' needs a training stretch (simulated scenarios only)", file=source,
                              key=f"{key}.{k}")
        return fit_coefficient(series[kind])

    t_fit = time.perf_counter()
    psi_m = {k: coefficient(v, k, f"measurement.{k}") for k, v in cc.measurement.items()}
    psi_p = coefficient(cc.process, "process", "process")
    channels = {}
    for k, v in cc.channels.items():
        name, _, cid = k.partition(":")
        if name not in ("pseudorange", "range_rate", "position", "velocity") or not cid.isdigit():
            raise ConfigError(f"a channel is '<observable>:<id>' (e.g. 'pseudorange:12', the PRN), got '{k}'",
                              file=source, key=f"{key}.channels.{k}")
        channels[(name, int(cid))] = v
    learning_time = time.perf_counter() - t_fit  # the AR(1) fits count as learning
    if mc.learn is not None:
        if not series:
            raise ConfigError(f"method '{method.name}' learns its mixtures from a training stretch, "
                              "which only simulated scenarios provide", file=source, key=f"methods[{index}].mixture.learn")
        t0 = time.perf_counter()
        white = {k: np.ravel(whiten_ar1(series[k], psi_m.get(k, 0.0))[1:]) for k in mc.learn.observables
                 if k in series}
        if mc.learn.learn_process and "process" in series:
            white["process"] = np.ravel(whiten_ar1(series["process"], psi_p)[1:])
        missing = [k for k in mc.learn.observables if k not in white]
        if missing:
            raise ConfigError(f"the coloured-noise filter learns pseudorange and range-rate mixtures, not {missing}",
                              file=source, key=f"methods[{index}].mixture.learn.observables")
        learned = _learn(mc, white, seed)
        mixtures, failed = learned.mixtures, learned.not_converged
        learning_time += time.perf_counter() - t0
    else:
        mixtures, failed = mixtures_from_config(mc), 0
    if any(v != 0.0 for v in psi_m.values()) or channels:  # all white: nothing to difference (exact)
        meas = [DifferencedMeasurement(m, layout, psi_m, channels) for m in meas]
    return ColoredMixtureEkf(layout, model, mixtures, psi_process=psi_p, psi_measurement=psi_m,
                             process_interval=cc.process_interval, max_components=mc.max_components,
                             learning_time_s=learning_time, learner_not_converged=failed, gate=mc.gate,
                             outlier_mean=mc.outlier_mean, divergence_window=mc.divergence_window,
                             divergence_nis=mc.divergence_nis, **common), meas


def _learn(mc: MixtureConfig, training: dict, seed: int):
    """The mixtures of ``mc.learn`` from training residuals (given ones kept)."""
    from ..noise.learn.offline import learn_mixtures
    lc = mc.learn
    return learn_mixtures(training, lc.observables, lc.method, mixtures_from_config(mc),
                          n_components=lc.n_components, gibbs_samples=lc.gibbs_samples, prune=lc.prune,
                          training_samples=lc.training_samples, learn_process=lc.learn_process, seed=seed)


def mixtures_from_config(cfg: MixtureConfig):
    """The given (not learned) mixtures of a ``[mixture]`` table."""
    from ..noise.mixture import BankMixtures, StandardMixture
    return BankMixtures({k: _spec(v) for k, v in cfg.measurement.items()},
                        _spec(cfg.process) if cfg.process is not None else StandardMixture.gaussian(),
                        _spec(cfg.prior) if cfg.prior is not None else StandardMixture.gaussian())


def _spec(s):
    from ..noise.mixture import StandardMixture
    return StandardMixture(tuple(s.weights), tuple(s.means or [0.0] * len(s.weights)), tuple(s.scales))
