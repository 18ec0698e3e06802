"""Simulated GNSS position/velocity fixes for loose coupling."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data import GnssFixes, Trajectory
from ..measurements.loose import antenna_lla
from ..attitude import quat_to_dcm
from ..geodesy.frames import displace


@dataclass(frozen=True)
class GnssFixModel:
    """How fixes are simulated.

    Attributes
    ----------
    rate : float
        Fixes per second [Hz].
    pos_sigma : ndarray (3,)
        1-sigma noise north, east, down [m].
    vel_sigma : ndarray (3,) or None
        1-sigma velocity noise [m/s]; ``None``: fixes carry no velocity.
    lever_arm : ndarray (3,)
        Antenna in the body frame relative to the IMU [m].
    outages : tuple of (start, end)
        Windows [s] with no fix (``start <= t < end``).
    """

    rate: float
    pos_sigma: np.ndarray
    vel_sigma: np.ndarray | None
    lever_arm: np.ndarray
    outages: tuple = ()


def in_windows(t: np.ndarray, windows) -> np.ndarray:
    """Boolean mask of the times inside any ``[start, end)`` window."""
    mask = np.zeros(np.shape(t), dtype=bool)
    for a, b in windows:
        mask |= (t >= a) & (t < b)
    return mask


def simulate_fixes(truth: Trajectory, model: GnssFixModel, rng: np.random.Generator,
                   noise=None, position_noise=None, velocity_noise=None, with_bias: bool = False):
    """Fixes of the antenna at every ``1/rate`` on the truth's time grid.

    Parameters
    ----------
    truth : Trajectory
        At the IMU rate; fix times must fall on its samples.
    model : GnssFixModel
    rng : numpy.random.Generator
        The run's ``gnss`` stream.
    noise : callable, optional
        ``noise(rng, shape) -> ndarray`` of unit-variance samples replacing
        the standard normal.
    position_noise, velocity_noise : mixnav.noise.processes.NoiseProcess, optional
        Noise processes (NED, per axis) replacing the Gaussian noise of that
        quantity; the fixes still carry the model's sigmas (what a filter is
        told).

    with_bias : bool
        Also return the systematic part of the position noise (the means of the mixture
        components drawn, bias segments; :meth:`~mixnav.noise.processes.NoiseProcess.sample_detail`).

    Returns
    -------
    GnssFixes
        Noise is added in NED metres and mapped to latitude/longitude with
        the radii at the fix.
    bias : ndarray (M, 3), only with ``with_bias``
        The systematic position error of each fix, NED [m] (zeros for Gaussian noise).
    """
    step = int(round(1.0 / (model.rate * np.median(np.diff(truth.time)))))
    idx = np.arange(step, len(truth.time), step)
    t = truth.time[idx]
    keep = ~in_windows(t, model.outages)
    idx, t = idx[keep], t[keep]
    noise = noise or (lambda g, shape: g.standard_normal(shape))
    lever = np.asarray(model.lever_arm, dtype=float)
    lla = np.empty((len(idx), 3))
    vel = np.empty((len(idx), 3))
    for j, k in enumerate(idx):
        nav = np.concatenate([truth.q_nb[k], truth.v_n[k], truth.lla[k]])
        lla[j] = antenna_lla(nav, lever)
        w_b = truth.extra.get("w_ib_b")
        w = w_b[k] if w_b is not None else np.zeros(3)
        vel[j] = truth.v_n[k] + quat_to_dcm(truth.q_nb[k]) @ np.cross(w, lever)
    bias = np.zeros((len(idx), 3))
    if position_noise is not None:
        dp, _, bias = position_noise.sample_detail(t, 3, rng)
    else:
        dp = noise(rng, (len(idx), 3)) * model.pos_sigma
    lla = displace(lla, dp)
    pos_sigma = np.tile(model.pos_sigma, (len(idx), 1))
    if model.vel_sigma is None:
        out = GnssFixes(time=t, lla=lla, pos_sigma=pos_sigma)
        return (out, bias) if with_bias else out
    if velocity_noise is not None:
        vel = vel + velocity_noise.sample(t, 3, rng)
    else:
        vel = vel + noise(rng, (len(idx), 3)) * model.vel_sigma
    out = GnssFixes(time=t, lla=lla, pos_sigma=pos_sigma, vel_n=vel,
                    vel_sigma=np.tile(model.vel_sigma, (len(idx), 1)))
    return (out, bias) if with_bias else out
