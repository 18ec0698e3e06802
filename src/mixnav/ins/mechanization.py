"""Free-inertial navigation: the validated entry point to the compiled kernels."""

from __future__ import annotations

import numpy as np

from ..attitude import quat_normalize
from ..data import ImuData, Trajectory
from ._kernels import mechanize_block


def nav_vector(q_nb, v_n, lla) -> np.ndarray:
    """Pack attitude, velocity and position into the kernels' ``nav`` (10,)."""
    nav = np.concatenate([quat_normalize(np.asarray(q_nb, float)), np.asarray(v_n, float),
                          np.asarray(lla, float)])
    if nav.shape != (10,) or not np.isfinite(nav).all():
        raise ValueError("nav_vector needs q_nb (4,), v_n (3,) and lla (3,), all finite")
    return nav


def free_inertial(imu: ImuData, nav0: np.ndarray) -> Trajectory:
    """Mechanize all increments from an initial state, with no aiding.

    Parameters
    ----------
    imu : ImuData
        Compensated increments.
    nav0 : ndarray (10,)
        Initial state (see :func:`nav_vector`) at ``imu.start_time``.

    Returns
    -------
    Trajectory
        N + 1 states: the initial one and one after each increment.
    """
    nav = np.array(nav0, dtype=float)
    if nav.shape != (10,):
        raise ValueError(f"nav0 must have shape (10,), got {nav.shape}")
    out = np.empty((len(imu) + 1, 10))
    out[0] = nav
    prev = np.zeros(6)
    mechanize_block(nav, prev, imu.dtheta, imu.dvel, imu.dt, out[1:])
    t = np.concatenate([[imu.start_time], imu.time])
    return Trajectory(time=t, lla=out[:, 7:10], v_n=out[:, 4:7], q_nb=out[:, 0:4])
