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

from ..engine.engine import Engine
from ..engine.result import FilterResult
from ..engine.smoother import rts_smooth
from ..errors import ConfigError

__all__ = ["make_estimator", "run_methods"]


def _check_smooth(method, source, index):
    from ..filters.registry import estimator_spec
    if not estimator_spec(method.estimator).can_smooth:
        raise ConfigError(f"estimator '{method.estimator}' cannot be smoothed (its registration says the RTS "
                          "smoother does not apply)", file=source, key=f"methods[{index}].smooth")


def make_estimator(method, source: str, index: int, seed: int = 0, model_name: str = "this motion model",
                   mixture_start: dict | None = None, motion_model=None):
    """The estimator of a method on any motion model, as the registry builds it
    (:func:`mixnav.experiment.methods.estimator_for`); errors named by their file key
    (``methods[index]...``). ``model_name`` (``"the dead-reckoning model"``) names the motion
    model; ``mixture_start``: the LOS/NLOS mixture a track alignment learned
    (:func:`mixnav.experiment.vehicle_process.mixture_handover`), the epoch mixture's starting
    values unless the method's options set them. ``motion_model``: the run's motion model
    object (for an estimator whose build needs it)."""
    from .methods import estimator_for
    motion = model_name.removeprefix("the ").removesuffix(" model")
    return estimator_for(method, source, index, seed, motion, mixture_start=mixture_start, motion_model=motion_model)


def run_methods(methods, make_motion, models, inputs, init, output_times, source: str, seed: int = 0,
                model_name: str = "this motion model", mixture_start: dict | None = None) -> dict[str, FilterResult]:
    """Run each ``(index, method)`` of ``methods``: a fresh motion model from ``make_motion()``,
    the method's estimator, the measurement ``models``, driven by ``inputs`` from ``init``,
    solutions at ``output_times``; ``method.smooth`` adds ``<name>-smoothed`` (RTS). The
    engine's random stream is ``seed`` for every method (the estimators that draw, draw
    from their own). ``mixture_start``: as :func:`make_estimator`."""
    results: dict[str, FilterResult] = {}
    for k, method in methods:
        motion = make_motion()
        est = make_estimator(method, source, k, seed, model_name, mixture_start, motion)
        if method.smooth:
            _check_smooth(method, source, k)
        res = Engine(motion, est, list(models), covariance_interval=1.0, rng=seed,
                     history=method.smooth).run(inputs, init, output_times=output_times)
        results[method.name] = res
        if method.smooth:
            results[f"{method.name}-smoothed"] = rts_smooth(res)
    return results
