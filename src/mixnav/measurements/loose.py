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

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock=None, memory=None, aux=None) -> Rows:
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

    def predict_batch(self, i: int, navs: np.ndarray, w_b: np.ndarray):
        """``h`` at a batch of full states, for the ensemble estimators.

        Returns ``(y, Y, R)``: the measurement ``y`` (m,) and the predictions ``Y``
        (N, m) of the states ``navs`` (N, 10), in one frame where ``y - Y[j]`` is the
        innovation of state ``j``: position as NED metres from the fix (so ``y``
        is zero there; radii at each state's antenna), velocity in NED [m/s];
        ``R`` (m,) the variances. ``w_b`` (3,) or (N, 3) body rate [rad/s].
        At the nominal state, ``y - Y[0]`` is :meth:`rows`' ``z``.
        """
        from ..geodesy.earth import radii
        navs = np.atleast_2d(np.asarray(navs, dtype=float))
        fix = self._rows[i]
        C = quat_to_dcm(navs[:, 0:4])                          # (N, 3, 3)
        cl = C @ self.lever                                     # (N, 3)
        lat, lon, h = navs[:, 7], navs[:, 8], navs[:, 9]
        rm, rn = radii(lat)
        a_lat = lat + cl[:, 0] / (rm + h)
        a_lon = lon + cl[:, 1] / ((rn + h) * np.cos(lat))
        a_h = h - cl[:, 2]
        rm_a, rn_a = radii(a_lat)
        dlon = (fix[1] - a_lon + np.pi) % (2.0 * np.pi) - np.pi
        Y = np.empty((len(navs), 6 if self.use_velocity else 3))
        Y[:, 0] = -(fix[0] - a_lat) * (rm_a + a_h)               # the antenna, NED from the fix
        Y[:, 1] = -dlon * (rn_a + a_h) * np.cos(a_lat)
        Y[:, 2] = (fix[2] - a_h)
        y = np.zeros(Y.shape[1])
        r = np.empty(Y.shape[1])
        r[:3] = fix[3:6] ** 2
        if self.use_velocity:
            wl = np.cross(np.broadcast_to(w_b, (len(navs), 3)), self.lever)
            Y[:, 3:6] = navs[:, 4:7] + np.einsum("nij,nj->ni", C, wl)
            y[3:6] = fix[6:9]
            r[3:6] = fix[9:12] ** 2
        return y, Y, r
