"""Simulated odometer: the forward speed of a wheel point in the vehicle frame.

Conventions (the odometer measurement models use the same): vehicle frame v
x forward, y right, z down; the IMU frame b is rotated from it by ``C_vb``;
the wheel point sits at ``l^b`` from the IMU (b frame). Its velocity in the
vehicle frame, the Earth-rate term ignored, is

    v^v = C_vb (C_bn v^n + w_nb^b x l^b)

and the odometer reads ``(1 + k) v^v_x + e``, ``e ~ N(0, sigma^2)``, sampled
at the instants (not averaged over the interval), optionally rounded to a
multiple of ``quantum`` [m/s] (a speed resolution; pulse counting is not
modelled). A reading below zero (noise at rest, or rounding) is clipped to
zero: an unsigned wheel-speed sensor cannot report reversing, so at a stop the
readings are ``max(e, 0)`` (half of them zero, the others half-normal, mean
``0.4 sigma``).
"""

from __future__ import annotations

import numpy as np

from ..attitude import quat_to_dcm
from ..data import OdometerData, Trajectory


def wheel_velocity(truth: Trajectory, idx, lever_arm, c_vb) -> np.ndarray:
    """``v^v`` of the wheel point at truth samples ``idx`` (rows), needs ``truth.extra["w_nb_b"]``."""
    c_nb = quat_to_dcm(truth.q_nb[idx])
    v_b = np.einsum("kji,kj->ki", c_nb, truth.v_n[idx]) + np.cross(truth.extra["w_nb_b"][idx],
                                                                   np.asarray(lever_arm, dtype=float))
    return v_b @ np.asarray(c_vb, dtype=float).T


def simulate_odometer(truth: Trajectory, rate: float, sigma: float, scale: float, lever_arm, c_vb,
                      rng: np.random.Generator, quantum: float | None = None,
                      source: str | None = None) -> OdometerData:
    """Odometer samples every ``1/rate`` s on the truth's samples (first at ``t0 + 1/rate``).

    Parameters
    ----------
    truth : Trajectory
        The IMU's truth (``q_nb`` the IMU's attitude) with ``extra["w_nb_b"]``.
    rate : float
        [Hz]; ``1/rate`` a whole number of truth intervals.
    sigma : float
        White noise std [m/s].
    scale : float
        Scale-factor error k (0.005 for 0.5 %).
    lever_arm : array (3,)
        Wheel point from the IMU, IMU frame b [m].
    c_vb : array (3, 3)
        IMU-to-vehicle rotation.
    rng : numpy Generator
        Draws the noise (one standard normal per sample, in time order).
    quantum : float, optional
        Speed resolution [m/s]: readings rounded to its multiples.

    Returns
    -------
    OdometerData
        ``sigma`` per sample is ``sqrt(sigma^2 + quantum^2 / 12)`` (the
        rounding error counted as uniform), or ``sigma`` without a quantum.
    """
    step = int(round(1.0 / (rate * np.median(np.diff(truth.time)))))
    idx = np.arange(step, len(truth.time), step)
    v_v = wheel_velocity(truth, idx, lever_arm, c_vb)
    speed = (1.0 + scale) * v_v[:, 0] + sigma * rng.standard_normal(len(idx))
    sig = sigma
    if quantum is not None:
        speed = quantum * np.round(speed / quantum)
        sig = float(np.sqrt(sigma ** 2 + quantum ** 2 / 12.0))
    speed = np.maximum(speed, 0.0) + 0.0  # + 0.0: no -0.0
    return OdometerData(time=truth.time[idx].copy(), speed=speed, sigma=np.full(len(idx), sig),
                        signed=False, source=source)
