"""Land-vehicle aiding: non-holonomic constraints, odometer, zero velocity, zero angular rate.

Frames: the body frame ``b`` is the IMU's (after the dataset's installation
rotation); the vehicle frame ``v`` is x forward, y right, z down. The IMU sits
in the vehicle at the mounting angles ``(roll, pitch, yaw)``:
``C_vb = C(roll, pitch, yaw)`` (``mixnav.attitude.euler_to_dcm``) takes body
vectors to the vehicle frame. The velocity of a vehicle point at lever arm
``l`` (body frame, from the IMU; e.g. the rear-axle centre, where the
constraints hold best) in the vehicle frame::

    v_v = C_vb (C_bn v_n + w_b x l)

(the Earth-rate part of ``w_nb``, below 1e-4 m/s for metre-size arms, is left
out of the prediction and the Jacobian, as in the loose GNSS model).

With the error state ``dx = x_true - x_est`` and ``C_true = exp([phi x]) C_est``
(``mixnav.ins.error_model``)::

    d v_b / d phi = C_bn [v_n x],   d v_b / d dv = C_bn,   d v_b / d dbg = [l x]

and for the optional mounting states (corrections of the mounting pitch and
yaw, auxiliary block ``mounting``; roll is not observable from these rows),
with ``C_vb = Rz(y) Ry(p) Rx(r)``::

    d v_v / d yaw = e_z x v_v,      d v_v / d pitch = (Rz(y) e_y) x v_v

* :class:`NonHolonomic`: ``v_v[1] = v_v[2] = 0`` (two rows, kind ``nhc``); with a
  suspension pitch gain ``k`` the vertical row expects ``v_v[2] = k a_x v_v[0]``
  (the body squats when the car accelerates and dives when it brakes: its x axis
  pitches by ``k a_x`` against the path), ``a_x`` the forward acceleration from the
  IMU's specific force (:func:`mean_specific_force`) and the nominal attitude.
* :class:`Odometer`: ``speed = (1 + k) v_v[0]`` with ``k`` the odometer scale
  error (auxiliary block ``odometer_scale`` when estimated; kind ``odometer``).
* :class:`ZeroVelocity` (ZUPT): ``v_n = 0`` at rest (three rows, kind ``zupt``).
* :class:`ZeroAngularRate` (ZARU): at rest the compensated gyro reads the Earth
  rate, ``w_b = C_bn w_ie_n``; the rows observe the gyro biases (kind ``zaru``).

The epochs of the ZUPT and ZARU models come from
:func:`mixnav.measurements.stillness.detect_still`.
"""

from __future__ import annotations

import numpy as np

from ..attitude import euler_to_dcm, quat_to_dcm, skew
from ..data import OdometerData
from ..errors import ArgumentError
from ..geodesy.earth import earth_rate_ned, normal_gravity
from ..ins.error_model import StateBlock, StateLayout
from ._vehicle_kernel import vehicle_velocity_jac
from .base import MeasurementModel, Rows
from .kinds import channel_id, register_kind

NHC = register_kind("nhc")
ODOMETER = register_kind("odometer")
ZUPT = register_kind("zupt")
ZARU = register_kind("zaru")

#: Auxiliary block of the mounting corrections: pitch, yaw of the IMU in the vehicle [rad].
MOUNTING = "mounting"
#: Auxiliary block of the odometer scale-factor error [fraction].
ODOMETER_SCALE = "odometer_scale"


def mounting_block(sigma0: float, walk: float = 0.0) -> StateBlock:
    """The mounting-correction states (pitch, yaw [rad]), initial 1-sigma ``sigma0`` [rad]."""
    return StateBlock(MOUNTING, 2, "random_walk", "aux", float(sigma0), float(walk), ("mount_pitch", "mount_yaw"))


def odometer_scale_block(sigma0: float, walk: float = 0.0) -> StateBlock:
    """The odometer scale-factor error state [fraction], initial 1-sigma ``sigma0``."""
    return StateBlock(ODOMETER_SCALE, 1, "random_walk", "aux", float(sigma0), float(walk), ("odo_scale",))


def _vec3(v, argument):
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ArgumentError(f"must be 3 finite numbers, got {v!r}", argument=argument)
    return a


def _sigma(v, argument):
    if not (np.isfinite(v) and v > 0):
        raise ArgumentError(f"must be a positive 1-sigma, got {v!r}", argument=argument)
    return float(v)


def _times(t, argument):
    t = np.asarray(t, dtype=float).ravel()
    if not np.all(np.isfinite(t)) or (len(t) > 1 and not np.all(np.diff(t) > 0)):
        raise ArgumentError("times must be finite and strictly increasing", argument=argument)
    return t


class VehicleVelocity(MeasurementModel):
    """Base of the models that see the velocity of a vehicle point in the vehicle frame.

    Parameters
    ----------
    layout : StateLayout
        With an auxiliary block ``mounting`` the mounting pitch/yaw corrections are
        estimated (:func:`mounting_block`).
    mounting : (3,) array
        Roll, pitch, yaw of the IMU body frame in the vehicle frame [rad].
    lever_arm : (3,) array
        The vehicle point in the body frame, from the IMU [m].
    """

    def __init__(self, layout: StateLayout, mounting=(0.0, 0.0, 0.0), lever_arm=(0.0, 0.0, 0.0)):
        if not isinstance(layout, StateLayout):
            raise ArgumentError(f"expected a StateLayout, got {type(layout).__name__}", argument="layout")
        self.layout = layout
        self.mounting = _vec3(mounting, "mounting")
        self.lever = _vec3(lever_arm, "lever_arm")
        self._n = layout.n
        self._mount = layout.slice(MOUNTING) if layout.has(MOUNTING) else None

    def vehicle_velocity(self, nav, w_b, aux=None):
        """``v_v`` (3,) [m/s] and its Jacobian over the error state (3, n) (one compiled
        call, :func:`mixnav.measurements._vehicle_kernel.vehicle_velocity_jac`)."""
        rpy = self.mounting
        if self._mount is not None and aux:
            est = aux[MOUNTING]
            rpy = np.array([rpy[0], rpy[1] + est[0], rpy[2] + est[1]])
        return vehicle_velocity_jac(np.asarray(nav, dtype=float), np.asarray(w_b, dtype=float), self.lever, rpy,
                                    self._n, -1 if self._mount is None else self._mount.start)


class NonHolonomic(VehicleVelocity):
    """Non-holonomic constraints: no lateral and no vertical velocity of the vehicle point.

    Parameters
    ----------
    times : (M,) array
        Epochs [s] (e.g. a regular grid at 1-10 Hz over the drive).
    layout, mounting, lever_arm
        See :class:`VehicleVelocity`.
    sigma : (2,) array or float
        1-sigma of the lateral and vertical velocity the vehicle really has
        (slip, bumps) [m/s].
    min_speed : float
        No rows while the nominal speed is below this [m/s] (the constraint
        still holds at rest, but a ZUPT says more there); 0 uses every epoch.
    pitch_per_accel : float
        Suspension pitch gain ``k`` [rad per m/s^2]: the vehicle frame's x axis
        pitches up by ``k a_x`` against the path when the car accelerates forward at
        ``a_x`` (squat; dive when braking), so the vertical row expects
        ``v_v[2] = k a_x v_v[0]`` instead of 0. 0 (default): the plain constraint.
    specific_force : (M, 3) array, optional
        The body-frame specific force [m/s^2] at each epoch, averaged over a short span
        before it (:func:`mean_specific_force`); required with ``pitch_per_accel``.
        ``a_x`` is its vehicle-frame x component plus that of gravity by the nominal
        attitude (the accelerometer bias, a few mg, is left out: 0.06 m/s^2 is below
        0.01 m/s^2 of expected vertical velocity at the gains and speeds of a car).
        An epoch whose average is not finite (outside the IMU's span) gets the plain row.
    """

    kinds = ("nhc",)

    def __init__(self, times, layout, mounting=(0.0, 0.0, 0.0), lever_arm=(0.0, 0.0, 0.0),
                 sigma=(0.1, 0.1), min_speed: float = 0.0, pitch_per_accel: float = 0.0, specific_force=None):
        super().__init__(layout, mounting, lever_arm)
        if not np.isfinite(pitch_per_accel):
            raise ArgumentError(f"must be finite, got {pitch_per_accel!r}", argument="pitch_per_accel")
        self.pitch_per_accel = float(pitch_per_accel)
        self._times = _times(times, "times")
        s = np.broadcast_to(np.asarray(sigma, dtype=float), (2,))
        for k in range(2):
            _sigma(s[k], "sigma")
        self.r = s ** 2
        if not (np.isfinite(min_speed) and min_speed >= 0):
            raise ArgumentError(f"must be >= 0 m/s, got {min_speed!r}", argument="min_speed")
        self.min_speed = float(min_speed)
        self._kinds = np.array([NHC, NHC], dtype=np.int64)
        self._channels = channel_id(self._kinds, np.array([1, 2]))
        self._f = None
        if self.pitch_per_accel != 0.0:
            if specific_force is None:
                raise ArgumentError("the suspension pitch needs the forward acceleration: pass the specific force "
                                    "at the epochs (mean_specific_force)", argument="specific_force")
            f = np.asarray(specific_force, dtype=float)
            if f.shape != (len(self._times), 3):
                raise ArgumentError(f"expected ({len(self._times)}, 3), got {f.shape}", argument="specific_force")
            self._f = f
            self._cvb_x = euler_to_dcm(self.mounting)[0]   # first row of C_vb = Rz(y) Ry(p) Rx(r)

    @property
    def times(self) -> np.ndarray:
        return self._times

    def forward_acceleration(self, i, nav) -> float:
        """``a_x`` [m/s^2] at epoch ``i``: the vehicle-frame x component of the specific
        force plus gravity (``f_b + C_bn g_n``), NaN where the specific force is unknown."""
        g = float(normal_gravity(nav[7], nav[9]))
        w, x, y, z = float(nav[0]), float(nav[1]), float(nav[2]), float(nav[3])
        # C_bn (0, 0, g) = g * (row 2 of C_nb), written out: quat_to_dcm's whole matrix, built with
        # np.stack per call, was most of an NHC row's cost (a 10 Hz NHC makes thousands a run)
        d = (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)
        f, c = self._f[i], self._cvb_x
        return float(c[0] * (f[0] + g * d[0]) + c[1] * (f[1] + g * d[1]) + c[2] * (f[2] + g * d[2]))

    def rows(self, i, nav, w_b, clock=None, memory=None, aux=None):
        if self.min_speed > 0 and np.dot(nav[4:7], nav[4:7]) < self.min_speed ** 2:
            return None
        v_v, H = self.vehicle_velocity(nav, w_b, aux)
        z = -v_v[1:3]
        if self._f is not None:
            a_x = self.forward_acceleration(i, nav)
            if np.isfinite(a_x):
                z[1] += self.pitch_per_accel * a_x * v_v[0]
        return Rows(z, H[1:3].copy(), self.r.copy(), self._kinds, self._channels)


def mean_specific_force(imu, times, span: float) -> np.ndarray:
    """The body-frame specific force [m/s^2] averaged over ``(t - span, t]`` at each of
    ``times`` (M, 3), from the IMU's velocity increments (whole increments that end in the
    span); NaN rows where no increment does."""
    t = np.asarray(times, dtype=float)
    if not (np.isfinite(span) and span > 0):
        raise ArgumentError(f"must be a positive time, got {span!r}", argument="span")
    cum_v = np.vstack([np.zeros(3), np.cumsum(imu.dvel, axis=0)])
    cum_t = np.concatenate([[0.0], np.cumsum(imu.dt)])
    hi = np.searchsorted(imu.time, t, side="right")
    lo = np.searchsorted(imu.time, t - span, side="right")
    dur = cum_t[hi] - cum_t[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (cum_v[hi] - cum_v[lo]) / dur[:, None]
    out[hi <= lo] = np.nan
    return out


class Odometer(VehicleVelocity):
    """Odometer: the forward speed of the wheel point, ``(1 + k) v_v[0]``.

    Parameters
    ----------
    data : OdometerData
        Speeds [m/s] and their 1-sigma, on the IMU time axis.
    layout, mounting, lever_arm
        See :class:`VehicleVelocity`; ``lever_arm`` to the wheel (or axle
        centre) the speed is of. With an auxiliary block ``odometer_scale`` the
        scale error ``k`` is estimated (:func:`odometer_scale_block`), otherwise
        it is ``scale`` (a known calibration).
    scale : float
        Known scale error ``k`` when it is not estimated [fraction].
    """

    kinds = ("odometer",)

    def __init__(self, data: OdometerData, layout, mounting=(0.0, 0.0, 0.0), lever_arm=(0.0, 0.0, 0.0),
                 scale: float = 0.0):
        if not isinstance(data, OdometerData):
            raise ArgumentError(f"expected OdometerData, got {type(data).__name__}", argument="data")
        super().__init__(layout, mounting, lever_arm)
        if not (np.isfinite(scale) and abs(scale) < 0.5):
            raise ArgumentError(f"must be a fraction in (-0.5, 0.5), got {scale!r}", argument="scale")
        self.data = data
        self.scale = float(scale)
        self._k = layout.slice(ODOMETER_SCALE).start if layout.has(ODOMETER_SCALE) else -1
        self._kinds = np.array([ODOMETER], dtype=np.int64)
        self._channels = channel_id(self._kinds, 0)

    @property
    def times(self) -> np.ndarray:
        return self.data.time

    def rows(self, i, nav, w_b, clock=None, memory=None, aux=None):
        v_v, H = self.vehicle_velocity(nav, w_b, aux)
        k = self.scale + (float(aux[ODOMETER_SCALE][0]) if self._k >= 0 and aux else 0.0)
        h = (1.0 + k) * v_v[0]
        Hr = (1.0 + k) * H[0:1]
        if self._k >= 0:
            Hr[0, self._k] = v_v[0]
        z = np.array([self.data.speed[i] - h])
        return Rows(z, Hr, np.array([self.data.sigma[i] ** 2]), self._kinds, self._channels)


class _AtRest(MeasurementModel):
    """Rows that hold only at rest (ZUPT, ZARU): epochs from the stillness detector, and no
    rows while the nominal speed is above ``max_speed`` [m/s]: an IMU alone cannot tell
    rest from a smooth constant-velocity drive (a simulated one, or a very smooth road),
    so a detection the navigation solution contradicts is not used."""

    def __init__(self, times, layout: StateLayout, sigma: float, max_speed: float, kind: int):
        self._times = _times(times, "times")
        self.r = np.full(3, _sigma(sigma, "sigma") ** 2)
        self.max_speed2 = _sigma(max_speed, "max_speed") ** 2
        self._kinds = np.full(3, kind, dtype=np.int64)
        self._channels = channel_id(self._kinds, np.arange(3))

    @property
    def times(self) -> np.ndarray:
        return self._times

    def moving(self, nav) -> bool:
        """The nominal moves faster than ``max_speed``."""
        return float(np.dot(nav[4:7], nav[4:7])) > self.max_speed2


class ZeroVelocity(_AtRest):
    """ZUPT: the IMU is at rest, ``v_n = 0`` (three rows, kind ``zupt``).

    Parameters
    ----------
    times : (M,) array
        Epochs detected still [s] (:func:`mixnav.measurements.stillness.detect_still`).
    layout : StateLayout
    sigma : float
        1-sigma of the velocity at rest (vibration, a creeping vehicle) [m/s].
    max_speed : float
        No rows while the nominal speed is above this [m/s] (see :class:`_AtRest`).
    """

    kinds = ("zupt",)

    def __init__(self, times, layout: StateLayout, sigma: float = 0.02, max_speed: float = 1.0):
        super().__init__(times, layout, sigma, max_speed, ZUPT)
        self._H = np.zeros((3, layout.n))
        self._H[:, layout.vel] = np.eye(3)

    def rows(self, i, nav, w_b, clock=None, memory=None, aux=None):
        if self.moving(nav):
            return None
        return Rows(-np.asarray(nav[4:7], dtype=float), self._H.copy(), self.r.copy(), self._kinds, self._channels)


class ZeroAngularRate(_AtRest):
    """ZARU: at rest the vehicle does not turn, so the compensated gyro should read the
    Earth rate, ``w_b = C_bn w_ie_n``; the innovation observes the gyro biases.

    ``h = w_b - C_bn w_ie_n`` (the turn rate relative to the Earth), measured 0;
    ``H_bg = -I``, ``H_phi = -C_bn [w_ie_n x]``.

    Parameters
    ----------
    times : (M,) array
        Epochs detected still [s].
    layout : StateLayout
    sigma : float
        1-sigma of one compensated rate sample at rest [rad/s]: the gyro's
        white noise over one IMU interval (``arw / sqrt(dt)``) plus vibration.
    max_speed : float
        No rows while the nominal speed is above this [m/s] (see :class:`ZeroVelocity`).
    """

    kinds = ("zaru",)

    def __init__(self, times, layout: StateLayout, sigma: float, max_speed: float = 1.0):
        super().__init__(times, layout, sigma, max_speed, ZARU)
        self._n = layout.n

    def rows(self, i, nav, w_b, clock=None, memory=None, aux=None):
        if self.moving(nav):
            return None
        C_bn = quat_to_dcm(nav[0:4]).T
        w_ie = earth_rate_ned(nav[7])
        H = np.zeros((3, self._n))
        H[:, 0:3] = -C_bn @ skew(w_ie)
        H[:, 9:12] = -np.eye(3)
        z = C_bn @ w_ie - np.asarray(w_b, dtype=float)
        return Rows(z, H, self.r.copy(), self._kinds, self._channels)
