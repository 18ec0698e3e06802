"""Building filters and measurement models from a method of a scenario or dataset file.

The configuration stops here: below this module every object takes plain,
validated Python arguments and names the *argument* that is wrong
(:class:`mixnav.errors.ArgumentError`); :func:`build` maps those to the
config file's keys (:func:`mixnav.config.errors.config_keys`). Estimators are
found by name in the registry (:mod:`mixnav.filters.registry`), which builds them from
their options: the method's ``[methods.options]``, or its own table (``[robust]``,
``[mixture]``, ``[imm]``), validated by the estimator's registered model. This module is
the generic part: find the spec, check the motion model, build the measurement models,
hand them to the estimator's build (its ``build_filter`` hook on the strapdown INS when it
registered one) and map argument errors to file keys. One builder serves every motion
model: :func:`build` (the strapdown INS: a filter) and :func:`estimator_for` (any other: an
estimator for the engine).
"""

from __future__ import annotations

from ..config.errors import config_keys
from ..config.loader import imu_model
from ..config.method_schema import MethodConfig
from ..errors import ConfigError
from ..filters.registry import METHOD_TYPES, BuildContext, check_motion, entry_options
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


def estimator_for(method, source, index: int, seed: int = 0, motion: str | None = None, training=None,
                  mixture_start: dict | None = None, motion_model=None):
    """The estimator of ``method`` (any entry with ``name``, ``estimator``, its estimator
    tables, ``options``) for a run on the named ``motion`` model, built by the registry;
    errors under the method's keys; ``motion_model``: the run's motion model object. The
    strapdown INS's filters come from :func:`build`."""
    key = f"methods[{index}]"
    motion = motion or "strapdown"
    with config_keys(key, source):
        spec = check_motion(method.estimator, motion)
    context = BuildContext(motion=motion_model, method=method, training=training, seed=seed, source=source, index=index,
                           extra={"mixture_start": mixture_start}, motion_name=motion, key=key)
    with config_keys(f"{key}.options", source):
        return spec.make(entry_options(method, spec), context=context)

#: Arguments of the measurement models -> the method's keys where they differ (an estimator's
#: own are its registration's ``keys``).
_RENAME = {"layout": "states"}


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
    with config_keys(f"methods[{index}]", source):
        spec = check_motion(method.estimator, "strapdown")
    with config_keys(f"methods[{index}]", source, {**_RENAME, **spec.keys}):
        filt, meas = _build(method, spec, default_imu, fixes, lever_arm, source, index, observations, clock,
                            training, seed, aiding)
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


def _build(method, spec, default_imu, fixes, lever_arm, source, index, observations, clock, training, seed, aiding):
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
    options = entry_options(method, spec)
    key = f"methods[{index}]"
    build_filter = spec.filter_builder(options)
    if build_filter is not None:   # an estimator that builds its whole filter (and may change the models)
        context = BuildContext(method=method, training=training, seed=seed, source=source, index=index, key=key,
                               motion_name="strapdown", measurements=meas + aids,
                               named_measurements={"gnss": meas[0], **dict(zip(method.aiding, aids))},
                               layout=layout, imu_model=model, covariance_interval=method.covariance_interval,
                               clock=clock)
        return build_filter(options, context)
    from ..filters.facade import Filter
    with config_keys(f"{key}.options", source):
        return Filter(method.estimator, layout, model, options, covariance_interval=method.covariance_interval,
                      clock=clock, context=BuildContext(method=method, training=training, seed=seed, source=source,
                                                        index=index)), meas + aids


def run_methods(methods, make_motion, models, inputs, init, output_times, source: str, seed: int = 0, *,
                motion: str, mixture_start: dict | None = None) -> dict:
    """Run each ``(index, method)`` of ``methods`` on a motion model other than the strapdown
    INS (the odometry datasets' dead reckoning, the raw-GNSS datasets' constant velocity): a
    fresh motion model from ``make_motion()``, the method's estimator from
    :func:`estimator_for` on the registry's ``motion`` model (``"dead-reckoning"``,
    ``"constant-velocity"``), the measurement ``models``, driven by ``inputs`` from ``init``,
    solutions at ``output_times``; one :class:`~mixnav.engine.Engine` each.
    ``method.smooth`` adds ``<name>-smoothed`` (the RTS smoother; an estimator whose
    registration says it cannot be smoothed is a ConfigError naming ``methods[k].smooth``).
    The engine's random stream is ``seed`` for every method (the estimators that draw, draw
    from their own). ``mixture_start``: the LOS/NLOS mixture a track alignment learned
    (:func:`mixnav.experiment.vehicle_process.mixture_handover`), the epoch mixture's starting
    values unless the method's options set them. A method entry is anything with ``name``,
    ``estimator``, ``robust``, ``mixture``, ``options`` and ``smooth``
    (:class:`mixnav.config.vehicle_schema.VehicleMethod` and its raw-GNSS subclass).
    Returns ``{name: FilterResult}``."""
    from ..engine.engine import Engine
    from ..engine.smoother import rts_smooth
    from ..filters.registry import estimator_spec
    results = {}
    for k, method in methods:
        motion_model = make_motion()
        est = estimator_for(method, source, k, seed, motion, mixture_start=mixture_start, motion_model=motion_model)
        if method.smooth and not estimator_spec(method.estimator).can_smooth:
            raise ConfigError(f"estimator '{method.estimator}' cannot be smoothed (its registration says the RTS "
                              "smoother does not apply)", file=source, key=f"methods[{k}].smooth")
        res = Engine(motion_model, est, list(models), covariance_interval=1.0, rng=seed,
                     history=method.smooth).run(inputs, init, output_times=output_times)
        results[method.name] = res
        if method.smooth:
            results[f"{method.name}-smoothed"] = rts_smooth(res)
    return results
