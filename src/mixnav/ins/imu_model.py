"""IMU error models and named grades in datasheet units.

The sensor model (per axis, every IMU interval of length dt)::

    dtheta_meas = (1 + sg) dtheta + (bg0 + bg_t) dt + ARW-noise
    dvel_meas   = (1 + sa) dvel   + (ba0 + ba_t) dt + VRW-noise

with the turn-on biases ``bg0, ba0`` and scale factors ``sg, sa`` drawn once
per run, the in-run biases ``bg_t, ba_t`` first-order Gauss-Markov processes
(steady-state sigma = bias instability, correlation time tau) plus an optional
random walk, and white noise whose increment variance is ``ARW^2 dt``.

The white noise is per sample by default: ``ARW sqrt(dt) x_i`` with ``x_i``
N(0, 1) or the samples of a configured unit-free process. With a *hold*
``T`` (a whole number of IMU intervals) the multiplier process is drawn once
per interval ``(t0 + kT, t0 + (k+1)T]`` and held as a rate noise::

    dtheta noise of sample i in interval k = x_k ARW dt_i / sqrt(T)

so the angle noise integrated over interval k is exactly ``x_k ARW sqrt(T)``
(variance ``ARW^2 T x_k^2``, the filter's Q over T times ``x_k^2``). The
epoch-level process noise then *is* the process ``x_k`` -- a mixture, or
P2's coloured ``W_k = H W_{k-1} + xi_k`` (P2 eqs. 1, 6) -- instead of being
averaged towards a Gaussian over the ~1/(dt) samples of an epoch.

The white noise (``arw``, ``vrw``) and the bias random walks
(``gyro_bias_walk``, ``accel_bias_walk``) may be given per body axis, as a
3-vector ``(x, y, z)``: a roof-mounted MEMS unit whose pitch gyro is ten
times noisier than its yaw gyro (drive-0708) cannot be described by one
value for all axes. The filter rotates a per-axis white noise into the
navigation frame (``Qc = C_nb diag(q_b) C_bn``, :mod:`mixnav.ins.error_model`);
equal values give exactly the scalar model.

Grades are written as a datasheet writes them and parsed by
:mod:`mixnav.units`, the one place units are converted.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from .. import units as u
from ..data import ImuData
from ..errors import ConfigError
from ..linalg import ar1_recursion

#: Datasheet text and dimension of every field, in field order.
FIELD_UNITS = {
    "gyro_bias": u.ANGULAR_RATE,
    "gyro_bias_instability": u.ANGULAR_RATE,
    "gyro_bias_tau": u.TIME,
    "gyro_bias_walk": u.GYRO_BIAS_DRIFT,
    "arw": u.ANGLE_RANDOM_WALK,
    "gyro_scale": u.DIMENSIONLESS,
    "accel_bias": u.ACCELERATION,
    "accel_bias_instability": u.ACCELERATION,
    "accel_bias_tau": u.TIME,
    "accel_bias_walk": u.ACCEL_BIAS_DRIFT,
    "vrw": u.VELOCITY_RANDOM_WALK,
    "accel_scale": u.DIMENSIONLESS,
}

#: Fields that may be a 3-vector of body-axis values (x, y, z) instead of one value.
PER_AXIS = ("arw", "vrw", "gyro_bias_walk", "accel_bias_walk")

GRADES: dict[str, dict[str, str]] = {
    # Ring-laser-gyro navigation grade (the P1 "RLG" row is of this class).
    "navigation": {
        "gyro_bias": "0.005 deg/h", "gyro_bias_instability": "0.003 deg/h", "gyro_bias_tau": "3600 s",
        "arw": "0.002 deg/sqrt(h)", "gyro_scale": "5 ppm",
        "accel_bias": "25 ug", "accel_bias_instability": "10 ug", "accel_bias_tau": "3600 s",
        "vrw": "5 ug/sqrt(Hz)", "accel_scale": "20 ppm",
    },
    # Fibre-optic / high-end MEMS tactical grade.
    "tactical": {
        "gyro_bias": "1 deg/h", "gyro_bias_instability": "0.5 deg/h", "gyro_bias_tau": "3600 s",
        "arw": "0.1 deg/sqrt(h)", "gyro_scale": "100 ppm",
        "accel_bias": "300 ug", "accel_bias_instability": "50 ug", "accel_bias_tau": "3600 s",
        "vrw": "50 ug/sqrt(Hz)", "accel_scale": "300 ppm",
    },
    # Industrial / automotive MEMS.
    "mems": {
        "gyro_bias": "10 deg/h", "gyro_bias_instability": "5 deg/h", "gyro_bias_tau": "3600 s",
        "arw": "0.3 deg/sqrt(h)", "gyro_scale": "1000 ppm",
        "accel_bias": "1 mg", "accel_bias_instability": "100 ug", "accel_bias_tau": "3600 s",
        "vrw": "100 ug/sqrt(Hz)", "accel_scale": "1000 ppm",
    },
}


@dataclass(frozen=True)
class ImuErrorModel:
    """IMU error parameters in SI units (rad, m, s); 1-sigma values.

    Attributes
    ----------
    gyro_bias : float
        Turn-on bias, drawn per run [rad/s].
    gyro_bias_instability : float
        Steady-state sigma of the in-run Gauss-Markov bias [rad/s].
    gyro_bias_tau : float
        Its correlation time [s] (``inf``: no Gauss-Markov part).
    gyro_bias_walk : float or tuple of 3 floats
        Bias random-walk density [rad/s^1.5]; per body axis when a 3-tuple.
    arw : float or tuple of 3 floats
        Angle random walk [rad/sqrt(s)]; per body axis when a 3-tuple.
    gyro_scale : float
        Scale-factor error, drawn per run [-].
    accel_* , vrw :
        The accelerometer counterparts [m/s^2, s, m/s^2.5, m/s^1.5, -]
        (``accel_bias_walk`` and ``vrw`` per axis as the gyro's).
    """

    gyro_bias: float = 0.0
    gyro_bias_instability: float = 0.0
    gyro_bias_tau: float = 3600.0
    gyro_bias_walk: float | tuple = 0.0
    arw: float | tuple = 0.0
    gyro_scale: float = 0.0
    accel_bias: float = 0.0
    accel_bias_instability: float = 0.0
    accel_bias_tau: float = 3600.0
    accel_bias_walk: float | tuple = 0.0
    vrw: float | tuple = 0.0
    accel_scale: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in PER_AXIS and not np.isscalar(v):
                v = tuple(float(x) for x in np.ravel(v))
                if len(v) != 3:
                    raise ConfigError(f"must be one value or three (x, y, z), got {len(v)}", key=f.name)
                object.__setattr__(self, f.name, v)
                bad = [x for x in v if not (x >= 0.0)]
                if bad:
                    raise ConfigError(f"must be non-negative, got {bad[0]!r}", key=f.name)
                continue
            if not (v >= 0.0):  # also catches NaN
                raise ConfigError(f"must be non-negative, got {v!r}", key=f.name)
        for tau in ("gyro_bias_tau", "accel_bias_tau"):
            if getattr(self, tau) <= 0.0:
                raise ConfigError("correlation time must be positive", key=tau)

    def axes(self, name: str) -> np.ndarray:
        """The field ``name`` (one of :data:`PER_AXIS`) per body axis, shape (3,) [SI]."""
        return np.broadcast_to(np.asarray(getattr(self, name), dtype=float), (3,)).copy()

    def is_per_axis(self, name: str) -> bool:
        """Whether ``name`` was given as three different body-axis values."""
        v = getattr(self, name)
        return not np.isscalar(v) and len(set(v)) > 1

    @classmethod
    def from_datasheet(cls, values: dict[str, str], grade: str | None = None,
                       source: str | None = None, key_prefix: str = "imu",
                       grade_key: str = "imu.grade") -> "ImuErrorModel":
        """Build from datasheet strings (``"2 deg/h"``), optionally over a grade.

        Parameters
        ----------
        values : dict
            Field name to quantity text; overrides the grade's entries. The
            fields of :data:`PER_AXIS` also take a list of three texts (x, y,
            z body axes).
        grade : str, optional
            One of :data:`GRADES`.
        """
        texts: dict = {}
        if grade is not None:
            if grade not in GRADES:
                raise ConfigError(f"unknown IMU grade '{grade}'; known: {', '.join(GRADES)}",
                                  file=source, key=grade_key)
            texts.update(GRADES[grade])
        texts.update(values)
        si = {}
        for name, text in texts.items():
            if name not in FIELD_UNITS:
                raise ConfigError(f"unknown IMU error field; known: {', '.join(FIELD_UNITS)}",
                                  file=source, key=f"{key_prefix}.{name}")
            if isinstance(text, (list, tuple)):
                if name not in PER_AXIS or len(text) != 3:
                    what = "three values (x, y, z)" if name in PER_AXIS else "one value"
                    raise ConfigError(f"takes {what}, got a list of {len(text)}",
                                      file=source, key=f"{key_prefix}.{name}")
            try:
                if isinstance(text, (list, tuple)):
                    si[name] = tuple(u.parse_quantity(t, FIELD_UNITS[name]) for t in text)
                else:
                    si[name] = u.parse_quantity(text, FIELD_UNITS[name])
            except u.UnitError as exc:
                raise ConfigError(str(exc), file=source, key=f"{key_prefix}.{name}") from None
        try:
            return cls(**si)
        except ConfigError as exc:
            raise ConfigError(exc.message, file=source, key=f"{key_prefix}.{exc.key}") from None

    def scaled_noise(self, factor: float) -> "ImuErrorModel":
        """The same model with white noise (ARW, VRW) scaled by ``factor``."""
        scale = lambda v: v * factor if np.isscalar(v) else tuple(x * factor for x in v)  # noqa: E731
        return replace(self, arw=scale(self.arw), vrw=scale(self.vrw))


@dataclass(frozen=True)
class ImuErrorDraw:
    """The per-run constants drawn from an :class:`ImuErrorModel` (SI)."""

    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_scale: np.ndarray
    accel_scale: np.ndarray


def _gauss_markov(rng, n, dt, sigma, tau):
    """Stationary first-order Gauss-Markov samples, shape (n, 3)."""
    if sigma == 0.0 or not np.isfinite(tau):
        return np.zeros((n, 3))
    a = np.exp(-dt / tau)
    w = rng.standard_normal((n, 3)) * sigma * np.sqrt(1.0 - a * a)
    x0 = rng.standard_normal(3) * sigma
    # x_k = a x_{k-1} + w_k, started in steady state.
    return ar1_recursion(w, np.full(3, a), x0)


def check_hold(hold: float, dt: float, duration: float) -> int:
    """Validate a white-noise hold interval; return it in IMU intervals.

    Parameters
    ----------
    hold : float
        Hold interval T [s].
    dt : float
        IMU interval [s].
    duration : float
        Length of the run [s].

    Returns
    -------
    int
        ``T / dt``, rounded.

    Raises
    ------
    ConfigError
        ``key="white_noise_hold"``: T not positive and finite, not a whole
        number of IMU intervals (to 1e-6 of one), or longer than the run.
    """
    if not (np.isfinite(hold) and hold > 0.0):
        raise ConfigError(f"must be positive, got {hold!r} s", key="white_noise_hold")
    m = round(hold / dt)
    if m < 1 or abs(hold / dt - m) > 1e-6:
        raise ConfigError(f"{hold:g} s is not a whole number of IMU intervals ({dt:g} s)",
                          key="white_noise_hold")
    if hold > duration * (1.0 + 1e-9):
        raise ConfigError(f"{hold:g} s is longer than the run ({duration:g} s)",
                          key="white_noise_hold")
    return int(m)


def hold_intervals(imu: ImuData, hold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which hold interval each IMU sample falls in.

    Parameters
    ----------
    imu : ImuData
        N samples; the grid starts at the first sample's start ``t0 = time[0] - dt[0]``.
    hold : float
        Hold interval T [s] (see :func:`check_hold`).

    Returns
    -------
    index : ndarray of int (N,)
        Interval k of each sample, the one holding its midpoint: ``(t0 + kT, t0 + (k+1)T]``.
    ends : ndarray (K,)
        End time of each interval [s], ``t0 + (k+1)T`` (the last one clipped to
        the last sample's time): the epochs the process is sampled at.
    length : ndarray (K,)
        Length of each interval covered by samples [s] (T except perhaps the last).
    """
    t0 = float(imu.time[0] - imu.dt[0])
    index = np.floor((imu.time - 0.5 * imu.dt - t0) / hold).astype(np.int64)
    k = int(index[-1]) + 1
    ends = np.minimum(t0 + hold * np.arange(1, k + 1), imu.time[-1])
    length = np.bincount(index, weights=imu.dt, minlength=k)
    return index, ends, length


def corrupt(imu: ImuData, model: ImuErrorModel, rng: np.random.Generator,
            white_noise: "callable | None" = None,
            hold: float | None = None) -> tuple[ImuData, ImuErrorDraw]:
    """Apply the error model to ideal increments.

    Parameters
    ----------
    imu : ImuData
        Ideal increments at a constant rate.
    model : ImuErrorModel
    rng : numpy.random.Generator
        The run's ``imu`` stream.
    white_noise : callable, optional
        ``white_noise(rng, times, n_channels) -> ndarray (len(times), n_channels)``
        of unit-variance samples at the epochs ``times`` [s], to replace the
        standard normal (non-Gaussian or coloured process noise scenarios).
        Called once for the gyro channels, then once for the accelerometer's.
    hold : float, optional
        Hold interval T [s]: draw the multiplier once per interval and hold
        it as a rate noise (module docstring; :func:`hold_intervals`). None:
        one draw per IMU sample.

    Returns
    -------
    ImuData, ImuErrorDraw
        The measured increments and the constants that were drawn.
    """
    n = len(imu)
    dt = float(np.median(imu.dt))
    draw = ImuErrorDraw(
        gyro_bias=rng.standard_normal(3) * model.gyro_bias,
        accel_bias=rng.standard_normal(3) * model.accel_bias,
        gyro_scale=rng.standard_normal(3) * model.gyro_scale,
        accel_scale=rng.standard_normal(3) * model.accel_scale,
    )
    noise = white_noise or (lambda g, times, c: g.standard_normal((len(times), c)))
    bg = draw.gyro_bias + _gauss_markov(rng, n, dt, model.gyro_bias_instability, model.gyro_bias_tau)
    ba = draw.accel_bias + _gauss_markov(rng, n, dt, model.accel_bias_instability, model.accel_bias_tau)
    # scalars stay scalars (the draws of a scalar model are unchanged); 3-tuples act per axis
    walk_g, walk_a = (v if np.isscalar(v) else np.asarray(v) for v in (model.gyro_bias_walk, model.accel_bias_walk))
    arw, vrw = (v if np.isscalar(v) else np.asarray(v) for v in (model.arw, model.vrw))
    if np.any(walk_g > 0):
        bg = bg + np.cumsum(rng.standard_normal((n, 3)) * walk_g * np.sqrt(dt), axis=0)
    if np.any(walk_a > 0):
        ba = ba + np.cumsum(rng.standard_normal((n, 3)) * walk_a * np.sqrt(dt), axis=0)
    if hold is None:
        times, scale, index = imu.time, np.sqrt(imu.dt)[:, None], slice(None)
    else:
        check_hold(hold, dt, float(imu.time[-1] - imu.time[0] + imu.dt[0]))
        index, times, length = hold_intervals(imu, hold)
        # zero-order-held rate noise: the increments of interval k sum to x_k sqrt(L_k)
        scale = (imu.dt / np.sqrt(length[index]))[:, None]
    dtheta = (1.0 + draw.gyro_scale) * imu.dtheta + bg * imu.dt[:, None] + \
        noise(rng, times, 3)[index] * arw * scale
    dvel = (1.0 + draw.accel_scale) * imu.dvel + ba * imu.dt[:, None] + \
        noise(rng, times, 3)[index] * vrw * scale
    return ImuData(time=imu.time, dt=imu.dt, dtheta=dtheta, dvel=dvel, source=imu.source), draw
