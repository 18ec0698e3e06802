"""Motion models beside the strapdown INS, on the same engine (floor 3).

The engine (:mod:`mixnav.engine`) drives any object with the
:class:`~mixnav.engine.protocols.MotionModel` methods: ``propagate`` over a block of
increments (filling ``Phi``, ``Qd`` and propagating one covariance), ``inject``
(feedback), ``initial_covariance``, ``warm_up`` and ``check_inputs`` (the increments it
is driven by). A run chooses its motion model by the object it hands the engine;
the run loop, the estimators and the measurement models are the same
(ARCHITECTURE.md, "Motion models").

- :class:`~mixnav.motion.dead_reckoning.DeadReckoningMotion`: a land vehicle driven by
  wheel speed and yaw rate (:func:`odometry_increments`).
- :class:`~mixnav.motion.constant_velocity.ConstantVelocityMotion`: GNSS-only users
  (driven by :func:`clock_ticks`).

Both keep the engine's nominal ``nav = [q_nb, v_n, lat, lon, h]``, so the GNSS
measurement models predict from it as they do for the INS.
"""

from .constant_velocity import ConstantVelocityMotion, clock_ticks
from .dead_reckoning import DeadReckoningMotion, OdometryIncrements, odometry_increments

__all__ = ["DeadReckoningMotion", "ConstantVelocityMotion", "OdometryIncrements", "odometry_increments",
           "clock_ticks"]
