"""mixnav: GNSS/INS integrated navigation when the noise is not Gaussian.

The notebook API (:mod:`mixnav.api`, imported on first use so ``import mixnav``
stays cheap): :func:`run_scenario`, :func:`process_dataset`, :func:`filter_loose`,
:func:`imu_grade`, :func:`export_rinex`, :func:`outage_sweep`,
:func:`start_sweep`, :func:`tune`. See docs/library.md.
"""

from ._version import __version__  # noqa: F401  (mixnav.__version__)


def _writable(path: str) -> bool:
    """Whether a file can be created in ``path`` (created if missing), as numba's cache does."""
    import os
    import tempfile
    try:
        os.makedirs(path, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
        return True
    except (OSError, ValueError):
        return False


def _numba_cache_usable() -> bool:
    """Whether numba can cache mixnav's compiled kernels: ``NUMBA_CACHE_DIR``, the
    ``__pycache__`` folders of the package, or the user-wide cache (``~/.cache/numba``)."""
    import os
    if os.environ.get("NUMBA_CACHE_DIR") and _writable(os.environ["NUMBA_CACHE_DIR"]):
        return True
    root = os.path.dirname(os.path.abspath(__file__))
    dirs = [d for d, _, files in os.walk(root) if any(f.endswith(".py") for f in files)
            and not os.path.basename(d) == "__pycache__"]
    if all(_writable(os.path.join(d, "__pycache__")) for d in dirs):
        return True
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return _writable(os.path.join(base, "numba"))


def _numba_without_cache() -> None:
    """No writable cache folder: compile without a cache (one warning), instead of numba's
    RuntimeError "cannot cache function ...: no locator available" at import."""
    import warnings
    from numba.core import dispatcher
    enable = dispatcher.Dispatcher.enable_caching
    if getattr(enable, "_mixnav_fallback", False):
        return

    def enable_caching(self):
        try:
            enable(self)
        except RuntimeError:  # no locator: leave this function uncached
            pass

    enable_caching._mixnav_fallback = True
    dispatcher.Dispatcher.enable_caching = enable_caching
    warnings.warn("mixnav: no writable folder for numba's cache of compiled code (the package's "
                  "__pycache__, ~/.cache/numba); compiling without a cache, so each command compiles "
                  "again. Set NUMBA_CACHE_DIR to a writable folder to keep it.", RuntimeWarning, stacklevel=2)


if not _numba_cache_usable():
    _numba_without_cache()

_API = ("run_scenario", "process_dataset", "run_experiment", "outage_sweep", "start_sweep", "tune", "filter_loose", "imu_grade", "export_rinex", "RunResult",
        "LooseResult", "ExperimentResult")


def __getattr__(name):
    if name in _API:
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module 'mixnav' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API))
