"""Loosely coupled GNSS position and velocity, with the antenna lever arm.

Two installation quantities can be estimated as auxiliary states (blocks of
the layout, :func:`gnss_lever_block`, :func:`time_offset_block`):

* ``gnss_lever`` (3, [m]): a correction ``dl`` of the configured antenna lever
  arm, ``l = l_cfg + dl`` (body frame). ``d h_pos / d dl = C_nb``,
  ``d h_vel / d dl = C_nb [w_b x]``: the position rows see it through the
  attitude changing, the velocity rows through the turn rate.
* ``imu_time_offset`` (1, [s]): a correction ``dt`` of the configured IMU time
  offset (``installation.imu_time_offset``, added to the IMU time tags): with
  the true offset ``o_cfg + dt`` the INS state labelled ``t`` is the state at
  true time ``t + dt``, so a fix at ``t`` is predicted by the state at label
  ``t - dt``: ``h_pos = p_ant - v_n dt``, ``h_vel = v_ant - a_n dt``, hence
  ``H_dt = -v_n`` and ``-a_n``. The acceleration ``a_n`` at each fix comes
  from differences of the fixes' own velocities (neighbours at most
  :data:`ACCEL_MAX_SPACING` away, :func:`fix_accelerations`); its error
  times the current offset is added to the velocity rows' variance. That
  matters: where a turn starts between two fixes the differenced acceleration
  is off by metres per second squared, and with centimetre-per-second RTK
  velocities an offset of 0.08 s then settled 12 sigma wrong in simulation
  (it is right with the added variance, ``tests/test_installation_states.py``).

At constant speed ``v`` in a straight line the forward lever component and the
offset move the predicted antenna alike (``l_x - v dt``): only speed changes
separate them, so estimated together on a drive with few of them they slide
along that ridge (docs/aiding.md, "Installation states").
"""

from __future__ import annotations

import numpy as np

from ..attitude import quat_to_dcm, skew
from ..data import GnssFixes
from ..errors import ArgumentError
from ..ins.error_model import StateBlock, StateLayout
from ._loose_kernel import loose_predict_batch, loose_zhr
from ._loose_members import pf_loose_update, pf_loose_update_serial, warm_loose_update
from .base import MeasurementModel, MemberUpdate, Rows
from .kinds import POSITION, VELOCITY, channel_id
from ..geodesy.frames import displace


#: Auxiliary block of the antenna lever-arm correction, body frame [m].
GNSS_LEVER = "gnss_lever"
#: Auxiliary block of the IMU time-offset correction [s].
TIME_OFFSET = "imu_time_offset"
#: Largest spacing of the fixes differenced for the acceleration of the time-offset rows [s].
ACCEL_MAX_SPACING = 1.0


def gnss_lever_block(sigma0: float, walk: float = 0.0) -> StateBlock:
    """The antenna lever-arm correction states (x, y, z body [m]), initial 1-sigma ``sigma0`` [m]."""
    return StateBlock(GNSS_LEVER, 3, "random_walk", "aux", float(sigma0), float(walk),
                      ("lever_x", "lever_y", "lever_z"))


def time_offset_block(sigma0: float, walk: float = 0.0) -> StateBlock:
    """The IMU time-offset correction state [s], initial 1-sigma ``sigma0`` [s]."""
    return StateBlock(TIME_OFFSET, 1, "random_walk", "aux", float(sigma0), float(walk), ("time_offset",))


def fix_accelerations(time: np.ndarray, vel_n: np.ndarray, vel_sigma: np.ndarray | None = None,
                      max_spacing: float = ACCEL_MAX_SPACING) -> tuple[np.ndarray, np.ndarray]:
    """NED acceleration at each fix and its 1-sigma [m/s^2], both (M, 3), from the
    neighbours' velocities.

    The acceleration is the mean of the backward and forward differences whose
    spacing is at most ``max_spacing`` [s] (one of them at the ends of a
    stretch; zero, with an unknown-sized sigma of 10 m/s^2, for an isolated fix):
    a withheld window or a gap is not differenced across. Its sigma is half the
    spread of the two differences (a jerk, a turn starting between the fixes)
    plus the velocity noise carried through a difference (``sqrt(2) sigma_v /
    spacing``); one-sided, the acceleration itself stands for the spread.
    """
    t = np.asarray(time, dtype=float)
    v = np.asarray(vel_n, dtype=float)
    m = len(t)
    acc = np.zeros_like(v)
    sig = np.full_like(v, 10.0)
    if m < 2:
        return acc, sig
    dt = np.diff(t)
    d = np.diff(v, axis=0) / dt[:, None]
    ok = dt <= max_spacing
    sv = np.zeros_like(v) if vel_sigma is None else np.asarray(vel_sigma, dtype=float)
    dn = np.sqrt(sv[1:] ** 2 + sv[:-1] ** 2) / dt[:, None]       # noise of each difference
    back = np.zeros(m, bool)
    back[1:] = ok                  # fix k has a backward difference d[k-1]
    fwd = np.zeros(m, bool)
    fwd[:-1] = ok                  # fix k has a forward difference d[k]
    db = np.zeros_like(v)
    db[1:] = d
    df = np.zeros_like(v)
    df[:-1] = d
    nb = np.zeros_like(v)
    nb[1:] = dn
    nf = np.zeros_like(v)
    nf[:-1] = dn
    both = back & fwd
    acc[both] = 0.5 * (db[both] + df[both])
    sig[both] = 0.5 * np.abs(df[both] - db[both]) + 0.5 * np.hypot(nb[both], nf[both])
    only_b = back & ~fwd
    acc[only_b] = db[only_b]
    sig[only_b] = np.abs(db[only_b]) + nb[only_b]
    only_f = fwd & ~back
    acc[only_f] = df[only_f]
    sig[only_f] = np.abs(df[only_f]) + nf[only_f]
    return acc, sig


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

    With an auxiliary block ``gnss_lever`` and/or ``imu_time_offset`` in the
    layout, those corrections are estimated (module docstring).
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
        self._channels = channel_id(self._kinds, np.arange(m) % 3)
        self._lever_sl = layout.slice(GNSS_LEVER) if layout.has(GNSS_LEVER) else None
        self._dt_col = layout.slice(TIME_OFFSET).start if layout.has(TIME_OFFSET) else -1
        self._acc, self._acc_sigma = (fix_accelerations(fixes.time, fixes.vel_n, fixes.vel_sigma)
                                      if self._dt_col >= 0 and self.use_velocity else (None, None))
        self._members_for = None   # (layout, its offset table or None): member_update's last answer

    kinds = ("position", "velocity")

    @property
    def times(self) -> np.ndarray:
        return self.fixes.time

    def rows(self, i: int, nav: np.ndarray, w_b: np.ndarray, clock=None, memory=None, aux=None) -> Rows:
        """The rows of fix ``i`` given the INS state ``nav`` and body rate ``w_b``:
        three position rows (NED [m]), then with velocity three velocity rows
        (NED [m/s]); ``R`` as its diagonal (independent axes)."""
        if (self._lever_sl is None and self._dt_col < 0) or not aux:
            z, H, r = loose_zhr(nav, self.lever, self._rows[i], w_b, self.use_velocity, self._n, self._i_bg)
            return Rows(z, H, r, self._kinds, self._channels)
        return self._rows_installation(i, nav, np.asarray(w_b, dtype=float), aux)

    def _rows_installation(self, i, nav, w_b, aux) -> Rows:
        """The rows with the estimated lever-arm and time-offset corrections (module docstring)."""
        lever = self.lever if self._lever_sl is None else self.lever + aux[GNSS_LEVER]
        z, H, r = loose_zhr(nav, lever, self._rows[i], w_b, self.use_velocity, self._n, self._i_bg)
        C = quat_to_dcm(nav[0:4])
        if self._lever_sl is not None:
            H[0:3, self._lever_sl] = C
            if self.use_velocity:
                H[3:6, self._lever_sl] = C @ skew(w_b)
        if self._dt_col >= 0:
            dt = float(aux[TIME_OFFSET][0])
            v = nav[4:7]
            z[0:3] += v * dt             # h_pos = p_ant - v dt
            H[0:3, self._dt_col] = -v
            H[0:3, 3:6] -= dt * np.eye(3)
            if self.use_velocity:
                a = self._acc[i]
                z[3:6] += a * dt         # h_vel = v_ant - a dt
                H[3:6, self._dt_col] = -a
                r[3:6] += (self._acc_sigma[i] * dt) ** 2   # the differenced acceleration's error
        return Rows(z, H, r, self._kinds, self._channels)

    def row_kinds(self, i: int, m: int) -> np.ndarray:
        """Kind codes of the rows of fix ``i`` (``m`` rows)."""
        return self._kinds[:m]

    def row_channels(self, i: int, m: int) -> np.ndarray:
        """A channel id per row, the same at every epoch (:func:`~mixnav.measurements.kinds.channel_id` of kind and axis)."""
        return self._channels[:m]

    def warm_up(self, nav: np.ndarray, aux: dict | None = None) -> None:
        """Compile (or load) the rows kernel and, where it serves, the batch prediction."""
        super().warm_up(nav, aux)
        if len(self.times) and self._lever_sl is None and self._dt_col < 0:
            self.predict_batch(0, np.array(nav, dtype=float)[None], np.zeros(3))

    def member_update(self, i: int, layout, parallel: bool = False) -> MemberUpdate | None:
        """The fused update of fix ``i`` for an ensemble of error states over ``layout``
        (:class:`~mixnav.measurements.base.MemberUpdate`; the particle filter's):
        :func:`~mixnav.measurements._loose_members.pf_loose_update` with the constants
        ``(layout array, lever arm (3,) [m], the fix's row (12,): lat, lon, h [rad, rad, m],
        position sigmas N, E, D [m], velocity NED and its sigmas [m/s]; the velocity part
        unused when use_velocity is off)``. None where :meth:`predict_batch` refuses (an
        estimated lever arm or time offset) or the members are not the INS error states
        of this model's layout (their attitude, velocity, position and gyro bias are read
        at the INS offsets)."""
        if self._lever_sl is not None or self._dt_col >= 0:
            return None
        arr = self._member_layout(layout)
        if arr is None:
            return None
        kernel = pf_loose_update if parallel else pf_loose_update_serial
        return MemberUpdate(6 if self.use_velocity else 3, kernel, (arr, self.lever, self._rows[i]))

    def _member_layout(self, layout):
        """The offset table of ``layout`` when its members can be read by the fused update (an
        INS layout of this model's size), else None; kept for the last layout asked."""
        last = self._members_for
        if last is not None and last[0] is layout:
            return last[1]
        ok = getattr(layout, "is_ins", False) and layout.n == self._n and layout.bg.start == self._i_bg
        arr = layout.as_array() if ok else None
        self._members_for = (layout, arr)
        return arr

    @classmethod
    def warm_up_members(cls, layout, parallel: bool = False) -> None:
        """Compile (or load) the fused update's kernel (``parallel``: its parallel twin) for both
        row counts (3, 6), for members over an INS ``layout``."""
        if getattr(layout, "is_ins", False):
            warm_loose_update(layout.as_array(), layout.n, parallel)

    def predict_batch(self, i: int, navs: np.ndarray, w_b: np.ndarray, clocks=None):
        """``h`` at a batch of full states, for the ensemble estimators.

        Returns ``(y, Y, R)``: the measurement ``y`` (m,) and the predictions ``Y``
        (N, m) of the states ``navs`` (N, 10), in one frame where ``y - Y[j]`` is the
        innovation of state ``j``: position as NED metres from the fix (so ``y``
        is zero there; radii at each state's antenna), velocity in NED [m/s];
        ``R`` (m,) the variances. ``w_b`` (3,) or (N, 3) body rate [rad/s].
        At the nominal state, ``y - Y[0]`` is :meth:`rows`' ``z``. ``clocks`` (the
        receiver clock of each state) is not used by the loose model.
        """
        if self._lever_sl is not None or self._dt_col >= 0:
            raise ArgumentError("the ensemble prediction does not carry the estimated lever arm or time "
                                "offset yet: use a layout without those blocks", argument="layout")
        navs = np.ascontiguousarray(np.atleast_2d(np.asarray(navs, dtype=float)))
        fix = self._rows[i]
        m = 6 if self.use_velocity else 3
        Y = np.empty((len(navs), m))
        w = np.ascontiguousarray(np.broadcast_to(np.asarray(w_b, dtype=float), (len(navs), 3)))
        loose_predict_batch(navs, self.lever, fix, w, self.use_velocity, Y)   # one compiled call
        y = np.zeros(m)
        r = np.empty(m)
        r[:3] = fix[3:6] ** 2
        if self.use_velocity:
            y[3:6] = fix[6:9]
            r[3:6] = fix[9:12] ** 2
        return y, Y, r
