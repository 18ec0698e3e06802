"""The filter a user runs for any registered estimator: the strapdown motion model, the
estimator (built by its registration, :mod:`mixnav.filters.registry`) and the engine.

``Filter("pf", layout, imu_model, {"particles": 500})`` is the particle filter;
:func:`facade` makes the named shortcuts the estimator modules export
(``ParticleFilter(layout, imu_model, particles=500)``). :class:`ErrorStateEkf` stays the
plain EKF. The estimators built from objects rather than options (the mixture bank, the
coloured bank, the IMM) give ``Filter`` a factory instead of a name: their public names
(``GaussianMixtureEkf``, ``ColoredMixtureEkf``, ``ImmEkf``) are functions returning it.
"""

from __future__ import annotations

from ..errors import ArgumentError
from .ekf import ErrorStateEkf
from .registry import BuildContext, check_motion
from .registry import ABSURD_SIGMA


class Filter(ErrorStateEkf):
    """Motion model + registered estimator + engine, behind ``run(imu, init, measurements)``.

    Parameters
    ----------
    estimator : str or callable
        A registered name (:func:`mixnav.filters.registry.estimator_names`) that runs on
        the strapdown INS, or a factory: a callable of no argument returning a fresh
        estimator per run (for estimators built from objects: mixtures, mode makers).
    layout, imu_model, covariance_interval, absurd_sigma, clock
        As :class:`~mixnav.filters.ekf.ErrorStateEkf`.
    options : dict or the estimator's options model, optional
        Its settings, validated now (a bad one: :class:`~mixnav.errors.ArgumentError`
        naming it); an ``absurd_sigma`` among them wins over the argument. Not with a factory.
    context : BuildContext, optional
        What an estimator's ``build`` needs beyond its options. Not with a factory.
    name, can_smooth
        With a factory: the estimator's name and whether the RTS smoother applies to
        its results (with a registered name both come from its registration).
    learning_time_s : float, optional
        Time spent learning the estimator's noise model, reported as the result's
        ``timing["learning_time_s"]`` (None: no entry).
    learner_not_converged : int
        Offline fits that did not converge, reported in ``recoveries`` when non-zero.
    attributes : dict, optional
        What callers read on the filter beyond these (the mixtures, coefficients...),
        set as its attributes.

    ``estimator`` holds the last run's estimator (None before a run).
    """

    def __init__(self, estimator, layout, imu_model, options=None, covariance_interval: float = 1.0,
                 absurd_sigma: float = ABSURD_SIGMA, clock=None, context: BuildContext | None = None, *,
                 name: str | None = None, can_smooth: bool = True, learning_time_s: float | None = None,
                 learner_not_converged: int = 0, attributes: dict | None = None):
        if callable(estimator):
            for argument, value in (("options", options), ("context", context)):
                if value is not None:
                    raise ArgumentError("a factory builds its estimator itself: give it no "
                                        f"{argument}", argument=argument)
            self.spec = self.options = self.context = None
            self._factory = estimator
        else:
            if name is not None:
                raise ArgumentError(f"a registered estimator is named by its registration ('{estimator}')",
                                    argument="name")
            self.spec = check_motion(estimator, "strapdown")
            self.options = self.spec.parse_options(options)
            if "absurd_sigma" in self.options.model_fields_set:
                absurd_sigma = self.options.absurd_sigma
            self._factory = None
        super().__init__(layout, imu_model, covariance_interval, absurd_sigma, clock)
        if self._factory is None:
            self.name = estimator
            self.can_smooth = self.spec.can_smooth
            self.context = context or BuildContext()
            self.context.motion = self.motion
        else:
            self.name = name
            self.can_smooth = bool(can_smooth)
        self.learning_time_s = None if learning_time_s is None else float(learning_time_s)
        self.learner_not_converged = int(learner_not_converged)
        for key, value in (attributes or {}).items():
            setattr(self, key, value)
        self.make_estimator()   # every setting checked now, not at the first run

    def make_estimator(self):
        if self._factory is not None:
            return self._factory()
        return self.spec.make(self.options, self.absurd_sigma, self.context)

    def run(self, imu, init, measurements=(), output_times=None, rng=None, history: bool = False):
        res = super().run(imu, init, measurements, output_times, rng, history)
        if self.learning_time_s is not None:
            res.timing["learning_time_s"] = self.learning_time_s
        if self.learner_not_converged:
            res.recoveries["learner_not_converged"] = self.learner_not_converged
        return res

    @property
    def online_learner(self):
        """The last run's online mixture learner (its ``history`` and counters), or None."""
        return getattr(self.estimator, "online", None)


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
