"""Receiver clock as a two-state random process (bias and drift, in metres).

The same model as the filter's :class:`mixnav.ins.error_model.ClockModel`,
so a simulation's truth is what a tight filter assumes::

    d(bias)/dt  = drift + w_b,   E[w_b w_b] = q_bias  [m^2/s]
    d(drift)/dt = w_d,           E[w_d w_d] = q_drift [m^2/s^3]

Sampled exactly between epochs (no Euler step): over ``dt`` the increment is
zero-mean Gaussian with covariance::

    [[q_b dt + q_d dt^3 / 3, q_d dt^2 / 2],
     [q_d dt^2 / 2,          q_d dt      ]]
"""

from __future__ import annotations

import numpy as np

__all__ = ["simulate_clock", "clock_increment_covariance"]


def clock_increment_covariance(dt: float, q_bias: float, q_drift: float) -> np.ndarray:
    """Covariance (2, 2) of the clock's random increment over ``dt`` [s]."""
    return np.array([[q_bias * dt + q_drift * dt ** 3 / 3, q_drift * dt ** 2 / 2],
                     [q_drift * dt ** 2 / 2, q_drift * dt]])


def simulate_clock(times: np.ndarray, q_bias: float, q_drift: float, bias0: float, drift0: float,
                   rng: np.random.Generator) -> np.ndarray:
    """Clock bias [m] and drift [m/s] at ``times`` (n,), starting from ``(bias0, drift0)`` at ``times[0]``.

    Returns
    -------
    ndarray (n, 2)
    """
    t = np.asarray(times, dtype=float)
    out = np.empty((len(t), 2))
    x = np.array([bias0, drift0], dtype=float)
    if len(t):
        out[0] = x
    z = rng.standard_normal((max(len(t) - 1, 0), 2))
    for k in range(1, len(t)):
        dt = t[k] - t[k - 1]
        x = np.array([x[0] + x[1] * dt, x[1]])
        if q_drift > 0 or q_bias > 0:  # a noiseless clock is a valid (deterministic) choice
            C = clock_increment_covariance(dt, q_bias, q_drift)
            if q_drift > 0:
                x = x + np.linalg.cholesky(C) @ z[k - 1]
            else:
                x[0] += np.sqrt(C[0, 0]) * z[k - 1, 0]
        out[k] = x
    return out
