"""The engine: one run loop (events, mechanization, clones, feedback, recording)
separate from the estimators it drives.

- :mod:`.protocols`: ``Estimator``, ``MotionModel``, ``Transition``, ``Correction``, ``Epoch``
  (the measurement-model protocol is :mod:`mixnav.measurements.base`);
- :mod:`.engine`: :class:`Engine` with a step API;
- :mod:`.result`: :class:`FilterResult`, :class:`History` (for smoothers);
- :mod:`.smoother`: :func:`rts_smooth` (fixed-interval RTS of a run with ``history=True``)
  and its array-level recursion :func:`rts_backward`;
- :mod:`.timing`: IMU increments split at event times;
- :mod:`.status`: status codes of an update.
"""

from .engine import Engine
from .protocols import Correction, Epoch, Estimator, MotionModel, Transition
from .result import FilterResult, History
from .smoother import rts_backward, rts_smooth

__all__ = ["Engine", "Correction", "Epoch", "Estimator", "MotionModel", "Transition", "FilterResult", "History",
           "rts_backward", "rts_smooth"]
