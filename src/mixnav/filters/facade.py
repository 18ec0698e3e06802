"""The filter a user runs for any registered estimator: the strapdown motion model, the
estimator (built by its registration, :mod:`mixnav.filters.registry`) and the engine.

``Filter("pf", layout, imu_model, {"particles": 500})`` is the particle filter;
:func:`facade` makes the named shortcuts the estimator modules export
(``ParticleFilter(layout, imu_model, particles=500)``). :class:`ErrorStateEkf` stays the
plain EKF; its table-driven relatives (the mixture bank, the coloured bank, the IMM) keep
their own constructors, which take objects rather than options.
"""

from __future__ import annotations

from .ekf import ErrorStateEkf
from .registry import BuildContext, check_motion
from .registry import ABSURD_SIGMA


class Filter(ErrorStateEkf):
    """Motion model + registered estimator + engine, behind ``run(imu, init, measurements)``.

    Parameters
    ----------
    estimator : str
        A registered name (:func:`mixnav.filters.registry.estimator_names`) that runs on
        the strapdown INS.
    layout, imu_model, covariance_interval, absurd_sigma, clock
        As :class:`~mixnav.filters.ekf.ErrorStateEkf`.
    options : dict or the estimator's options model, optional
        Its settings, validated now (a bad one: :class:`~mixnav.errors.ArgumentError`
        naming it); an ``absurd_sigma`` among them wins over the argument.
    context : BuildContext, optional
        What an estimator's ``build`` needs beyond its options.
    """

    def __init__(self, estimator: str, layout, imu_model, options=None, covariance_interval: float = 1.0,
                 absurd_sigma: float = ABSURD_SIGMA, clock=None, context: BuildContext | None = None):
        self.spec = check_motion(estimator, "strapdown")
        self.options = self.spec.parse_options(options)
        if "absurd_sigma" in self.options.model_fields_set:
            absurd_sigma = self.options.absurd_sigma
        super().__init__(layout, imu_model, covariance_interval, absurd_sigma, clock)
        self.name = estimator
        self.can_smooth = self.spec.can_smooth
        self.context = context or BuildContext()
        self.context.motion = self.motion
        self.make_estimator()   # every setting checked now, not at the first run

    def make_estimator(self):
        return self.spec.make(self.options, self.absurd_sigma, self.context)


def facade(name: str, public_name: str):
    """``public_name(layout, imu_model, *, covariance_interval=1.0, absurd_sigma=ABSURD_SIGMA, clock=None,
    **options)``: the :class:`Filter` of estimator ``name`` (keywords only: the old classes'
    positional order differed per estimator)."""
    def make(layout, imu_model, *, covariance_interval: float = 1.0, absurd_sigma: float = ABSURD_SIGMA, clock=None,
             **options) -> Filter:
        return Filter(name, layout, imu_model, options, covariance_interval, absurd_sigma, clock)
    make.__name__ = make.__qualname__ = public_name
    make.__doc__ = (f"The filter of estimator '{name}' on the strapdown INS: ``Filter('{name}', ...)`` "
                    "with its options as keywords (:mod:`mixnav.filters.facade`).")
    return make
