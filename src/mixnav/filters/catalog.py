"""The old catalogue of estimator names, now a view of :mod:`mixnav.filters.registry`
(kept for code that imports it; new code asks the registry).

``ESTIMATORS``: registered name -> one-line description (imports every estimator module,
so it is built only when asked); :func:`filter_class`: the filter maker of a name.
"""

from __future__ import annotations

from .registry import METHOD_TYPES  # noqa: F401  (re-exported)
from .registry import ABSURD_SIGMA


def __getattr__(name):
    if name == "ESTIMATORS":
        from .registry import estimator_names, estimator_spec
        return {n: estimator_spec(n).description for n in estimator_names()}
    raise AttributeError(name)


def filter_class(name: str):
    """``maker(layout, imu_model, **options)``: the :class:`~mixnav.filters.facade.Filter` of
    the estimator registered as ``name`` (checked now: an unknown name lists the known ones)."""
    from .facade import Filter
    from .registry import check_motion
    check_motion(name, "strapdown")

    def maker(layout, imu_model, covariance_interval: float = 1.0, absurd_sigma: float = ABSURD_SIGMA, clock=None,
              **options):
        return Filter(name, layout, imu_model, options, covariance_interval, absurd_sigma, clock)
    return maker
