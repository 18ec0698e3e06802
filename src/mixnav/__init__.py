"""mixnav: GNSS/INS integrated navigation when the noise is not Gaussian.

The notebook API (:mod:`mixnav.api`, imported on first use so ``import mixnav``
stays cheap): :func:`run_scenario`, :func:`process_dataset`, :func:`filter_loose`,
:func:`imu_grade`. See docs/library.md.
"""

__version__ = "0.1.0"

_API = ("run_scenario", "process_dataset", "filter_loose", "imu_grade", "RunResult", "LooseResult")


def __getattr__(name):
    if name in _API:
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module 'mixnav' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API))
