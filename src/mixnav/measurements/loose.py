"""Loosely coupled GNSS position and velocity, with the antenna lever arm."""

from __future__ import annotations

import numpy as np

from ..attitude import quat_to_dcm
from ..data import GnssFixes
from ..ins.error_model import StateLayout
from ._loose_kernel import loose_zhr
from .base import MeasurementModel, Rows
from .kinds import POSITION, VELOCITY
from ..geodesy.frames import displace


def antenna_lla(nav: np.ndarray, lever_b: np.ndarray) -> np.ndarray:
    """Geodetic position of a point at ``lever_b`` (body frame, [m]) from the IMU."""
    return displace(nav[7:10], quat_to_dcm(nav[0:4]) @ lever_b)


class LooseGnss(MeasurementModel):
    """GNSS position (and velocity, when the fixes have it) in the error-state EKF.

    Innovations (true minus estimated antenna quantities)::

        z_pos = p_gnss - (p_ins + C_nb l_b)           in NED [m]
        z_vel = v_gnss - (v_ins + C_nb (w_ib^b x l_b))  [m/s]

    Jacobians (``dx = x_true - x_est``, ``C_true = exp(phi) C_est``)::

        H_pos = [ -[(C l) x],        0, I, 0,        0 ]
        H_vel = [ -[(C (w x l)) x],  I, 0, C [l x],  0 ]

    The term ``-w_in^n x (C l)`` of the antenna velocity (Earth and transport
    rate acting on the lever arm, below 1e-4 m/s for metre-size arms) is left
    out of both the prediction and the Jacobian.

    Parameters
    ----------
    fixes : GnssFixes
    lever_arm : ndarray (3,)
        Antenna position in the body frame relative to the IMU [m].
    layout : StateLayout
    use_velocity : bool
        Use the velocity of the fixes when they have one.
    """

    def __init__(self, fixes: GnssFixes, lever_arm, layout: StateLayout, use_velocity: bool = True):
        self.fixes = fixes
        self.lever = np.asarray(lever_arm, dtype=float).reshape(3)
        self.layout = layout
        self.use_velocity = use_velocity and fixes.vel_n is not None
        # one row per fix for the compiled model: lla, pos sigma, vel, vel sigma
        m = len(fixes)
        vel = fixes.vel_n if self.use_velocity else np.zeros((m, 3))
        vsig = fixes.vel_sigma if self.use_velocity else np.ones((m, 3))
        self._rows = np.ascontiguousarray(np.hstack([fixes.lla, fixes.pos_sigma, vel, vsig]))
        self._n = layout.n
        self._i_bg = layout.bg.start
        m = 6 if self.use_velocity else 3
        self._kinds = np.array([POSITION] * 3 + [VELOCITY] * (m - 3), dtype=np.int64)
        self._channels = self._kinds * 1000 + np.arange(m) % 3

    kinds = ("position", "velocity")

    @property
    def times(self) -> np.ndarray:
        return self.fixes.time

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock=None, memory=None) -> Rows:
        """The rows of fix ``i`` given the INS state ``nav`` and body rate ``w_b``:
        three position rows (NED [m]), then with velocity three velocity rows
        (NED [m/s]); ``R`` as its diagonal (independent axes)."""
        z, H, r = loose_zhr(nav, self.lever, self._rows[i], w_b, self.use_velocity, self._n, self._i_bg)
        return Rows(z, H, r, self._kinds, self._channels)

    def row_kinds(self, i: int, m: int) -> np.ndarray:
        """Kind codes of the rows of fix ``i`` (``m`` rows)."""
        return self._kinds[:m]

    def row_channels(self, i: int, m: int) -> np.ndarray:
        """A channel id per row, the same at every epoch: ``kind * 1000 + axis``."""
        return self._channels[:m]
