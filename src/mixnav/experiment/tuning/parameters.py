"""What ``mixnav tune`` tunes in a dataset file, and how a value is read from and written to it.

A :class:`Parameter` is one key of the dataset file (a TOML path; a vector key may be tuned
as a whole or by element), its physical dimension and the unit it is written in, and how the
search moves it: ``"log"`` multiplies it by factors (noise densities, sigmas: scale
parameters), ``"shift"`` adds offsets (times). Values are SI inside, one array per key, and
are written back as text with their unit (``"0.151 deg/s/sqrt(Hz)"``), keeping the key's
shape (a per-axis list stays a list).

:func:`ins_parameters` lists what is tuned for an IMU + GNSS-fixes dataset. The file is
edited as a :mod:`tomlkit` document, so its comments and layout survive into ``tuned.toml``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import tomlkit

from ... import units as u

_SQRT2 = float(np.sqrt(2.0))


@dataclass(frozen=True)
class Parameter:
    """One tuned key.

    Attributes
    ----------
    name : str
        The dotted key as the report and ``--fix`` name it (``"imu.errors.arw"``,
        ``"aiding.nhc.sigma[1]"`` for one element).
    path : tuple of str
        The TOML path of the key.
    dimension : units.Dimension
    unit : str
        The unit the value is written in.
    kind : str
        ``"log"`` (scaled by factors) or ``"shift"`` (offsets in SI).
    coarse, fine : tuple of float
        The moves of the search's coarse and fine passes (factors or SI offsets).
    lower, upper : float
        Bounds in SI.
    index : int or None
        The element of a vector key this parameter moves (None: the whole key).
    default : float, tuple or None
        The key's whole value when the file lacks it (the schema's default), SI; None: a
        missing key is not tuned.
    about : str
        What the parameter is, for the report.
    plain : bool
        The key takes a plain number in ``unit`` (the schema's own unit, not written out:
        e.g. the clock noise in m^2/s).
    zero_from : float or None
        SI; a ``"log"`` key at zero is moved by a factor ``s > 1`` to ``s * zero_from`` (None:
        ``s * lower``): where a zero key's meaningful scale is the data's (the fixes' sigma
        floor from the fixes' own sigmas).
    judged_by : str
        What the search minimises along this key: ``"criterion"`` (the tuner's own: the
        cross-validation NLPD for fixes) or ``"innovation"`` (minus the GNSS innovation
        log-likelihood per update of the same runs): the timing keys, which a misregistration
        shows in every update (docs/tuning.md, "Which criterion a key follows").
    carries : tuple of (Parameter, float)
        Keys moved with this one: for a ``"shift"`` key each by its coefficient times this
        key's shift; for a ``"log"`` key each multiplied by this key's factor to the power of
        its coefficient (the NHC rate carries its sigmas by the square root). The IMU clock drift carries the time offset by minus the tuning span's
        centre, so that a drift step turns the clock about the span's middle instead of
        its start (set by the tuner, which knows the span: ``pivoted``).
    length : int or None
        With ``index``: the vector's length a one-value key is spread to before its element is
        moved (a scalar ARW is the same on three axes).
    data_steps : tuple of float
        Moves measured from the data, tried with the coarse grid (set by the tuner: the IMU
        time offset's turn-rate lag when it lies beyond the grid's reach); when one wins, the
        coarse grid is tried again about it.
    """

    name: str
    path: tuple
    dimension: object
    unit: str
    kind: str
    coarse: tuple
    fine: tuple
    lower: float
    upper: float
    index: int | None = None
    default: float | tuple | None = None
    about: str = ""
    plain: bool = False
    zero_from: float | None = None
    judged_by: str = "criterion"
    carries: tuple = ()
    length: int | None = None
    data_steps: tuple = ()

    @property
    def scale(self) -> float:
        """The unit's size in SI."""
        return 1.0 if self.plain else float(u.parse_quantity(f"1 {self.unit}", self.dimension))


_LOG_COARSE, _LOG_FINE = (0.25, 0.5, 2.0, 4.0), (1 / _SQRT2, _SQRT2)

#: the IMU clock against GNSS time (``installation.imu_clock_drift``): over a 4-minute span,
#: 100 ppm moves the stamps at its ends by 12 ms against its middle, half the time offset's
#: fine step; the coarse steps reach the 257 ppm drive-0708's tags show under the data
#: README's reading (docs/data_formats.md, "drive-0708 time tags")
IMU_CLOCK_DRIFT = Parameter(
    "installation.imu_clock_drift", ("installation", "imu_clock_drift"), u.DIMENSIONLESS, "ppm", "shift",
    (-300e-6, -100e-6, 100e-6, 300e-6), (-50e-6, 50e-6), -5e-3, 5e-3, default=0.0, judged_by="innovation",
    about="the rate at which the IMU time offset grows (the IMU clock against GNSS time)")


#: the NHC rate, searched last of all, after the conservative pass, on its coarse grid only (a 5 Hz
#: run costs two 1 Hz ones: every other key is searched at the file's rate). A rate step carries
#: both sigmas by its square root, so that
#: the constraint's information per second stays: the candidates differ in how evenly the
#: constraint is spread over time, not in how hard it holds. Up to 5 Hz: on drive-0708 the
#: innovation likelihood is flat from 2 to 50 Hz and lower at 1 Hz
#: (benchmarks/results/drive0708_drift.md, "The NHC rate"), while the cost grows with the rate
#: (up to 10 Hz the whole drive took 121 s to tune, past the 2-minute bound)
NHC_RATE = Parameter(
    "aiding.nhc.rate", ("aiding", "nhc", "rate"), u.FREQUENCY, "Hz", "log", (2.0, 5.0), _LOG_FINE, 0.1, 5.0,
    default=1.0, about="NHC updates per second (its sigmas carried by the square root of the step)",
    carries=((Parameter("aiding.nhc.sigma", ("aiding", "nhc", "sigma"), u.VELOCITY, "m/s", "log", (), (), 1e-3, 10.0,
                        default=(0.1, 0.1)), 0.5),))


def pivoted(p: Parameter, offset: Parameter, centre: float) -> Parameter:
    """``p`` (the clock drift) carrying ``offset`` so that a drift step leaves the stamps at
    ``centre`` [s since the first IMU sample] where they were."""
    from dataclasses import replace
    return replace(p, carries=((offset, -float(centre)),))


def ins_parameters() -> list[Parameter]:
    """The tuned keys of an IMU + GNSS-fixes dataset, in the order the search visits them."""
    arw, vrw = u.ANGLE_RANDOM_WALK, u.VELOCITY_RANDOM_WALK
    # the systematic keys first: a wrong time offset or velocity delay would otherwise be absorbed
    # by the noise scales the search visits next. They follow the innovation likelihood: a timing
    # error shows in every update (velocity x dynamics), which thousands of updates resolve to
    # 0.025 s, while the cross-validation's change over that grid (0.003-0.02 per fix on
    # drive-0708's halves) lies far inside its own standard error (0.2-0.5)
    return [
        Parameter("installation.imu_time_offset", ("installation", "imu_time_offset"), u.TIME, "s", "shift",
                  (-0.1, -0.05, 0.05, 0.1), (-0.025, 0.025), -1.0, 1.0, default=0.0, judged_by="innovation",
                  about="IMU time tags minus GNSS time"),
        IMU_CLOCK_DRIFT,
        Parameter("gnss.velocity_delay", ("gnss", "velocity_delay"), u.TIME, "s", "shift",
                  (-0.1, -0.05, 0.05, 0.1), (-0.025, 0.025), 0.0, 1.0, default=0.0, judged_by="innovation",
                  about="how much earlier than its epoch a GNSS velocity is valid"),
        # the odometer's stamps against the IMU's (a CAN speed can arrive after the wheel turned;
        # on comma2k19-example1 a cross-correlation says 0.08 s, benchmarks/results/comma2k19_odometer.md,
        # while the filter's own innovations and this criterion peak at 0: docs/tuning.md). It follows the
        # cross-validation: the odometer carries the dead reckoning of the withheld windows, while
        # the innovation likelihood counts the GNSS updates only, which the odometer hardly moves
        Parameter("aiding.odometer.time_offset", ("aiding", "odometer", "time_offset"), u.TIME, "s", "shift",
                  (-0.1, -0.05, 0.05, 0.1), (-0.025, 0.025), -1.0, 1.0, default=0.0,
                  about="added to the odometer file's stamps (minus the speeds' lag behind the IMU)"),
        Parameter("imu.errors.arw", ("imu", "errors", "arw"), arw, "deg/s/sqrt(Hz)", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-7, 1e-1, about="gyro white noise (ARW), per axis; the search scales all axes"),
        # the vertical gyro on its own after the three together: a car's body shakes in roll and
        # pitch far more than in yaw (drive-0708's still segments: z a third to a seventh of x, y)
        Parameter("imu.errors.arw[2]", ("imu", "errors", "arw"), arw, "deg/s/sqrt(Hz)", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-7, 1e-1, index=2, length=3, about="the vertical (z) gyro's white noise alone"),
        Parameter("imu.errors.vrw", ("imu", "errors", "vrw"), vrw, "ug/sqrt(Hz)", "log", _LOG_COARSE, _LOG_FINE,
                  1e-7, 1.0, about="accelerometer white noise (VRW), per axis; the search scales all axes"),
        Parameter("aiding.nhc.sigma[0]", ("aiding", "nhc", "sigma"), u.VELOCITY, "m/s", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-3, 10.0, index=0, default=(0.1, 0.1), about="NHC lateral velocity sigma"),
        Parameter("aiding.nhc.sigma[1]", ("aiding", "nhc", "sigma"), u.VELOCITY, "m/s", "log", _LOG_COARSE,
                  _LOG_FINE, 1e-3, 10.0, index=1, default=(0.1, 0.1), about="NHC vertical velocity sigma"),
        Parameter("aiding.vehicle_point[0]", ("aiding", "vehicle_point"), u.LENGTH, "m", "shift",
                  (-2.0, -1.0, 1.0, 2.0), (-0.5, 0.5), -6.0, 6.0, index=0, default=(0.0, 0.0, 0.0),
                  about="where the NHC holds (the rear axle), forward of the IMU: in a turn the IMU "
                        "moves sideways by the yaw rate times this distance"),
        Parameter("aiding.nhc.pitch_per_accel", ("aiding", "nhc", "pitch_per_accel"), u.Dimension(1.0, -1.0, 2.0),
                  "deg/(m/s^2)", "shift", tuple(x * u.DEG for x in (-0.4, -0.2, 0.2, 0.4)),
                  (-0.1 * u.DEG, 0.1 * u.DEG), -3.0 * u.DEG, 3.0 * u.DEG, default=0.0,
                  about="the body's pitch on its suspension per m/s^2 of forward acceleration"),
        Parameter("imu.errors.gyro_bias_walk", ("imu", "errors", "gyro_bias_walk"), u.GYRO_BIAS_DRIFT,
                  "deg/s^2/sqrt(Hz)", "log", (1 / 8, 0.25, 0.5, 2.0, 4.0, 8.0), _LOG_FINE, 1e-10, 1e-1,
                  about="gyro bias random walk"),
        Parameter("imu.errors.accel_bias_walk", ("imu", "errors", "accel_bias_walk"), u.ACCEL_BIAS_DRIFT,
                  "ug/s/sqrt(Hz)", "log", (1 / 8, 0.25, 0.5, 2.0, 4.0, 8.0), _LOG_FINE, 1e-10, 1.0,
                  about="accelerometer bias random walk"),
        Parameter("gnss.min_sigma", ("gnss", "min_sigma"), u.LENGTH, "m", "log", _LOG_COARSE, _LOG_FINE,
                  1e-3, 100.0, default=0.0, about="floor of the fixes' position sigmas"),
        NHC_RATE,
    ]


def _node(doc, path, create: bool = False):
    """The table holding the last key of ``path`` (None when absent and not ``create``)."""
    t = doc
    for k in path[:-1]:
        if isinstance(k, int):       # an element of an array of tables ([[methods]]): never created
            t = t[k]
            continue
        if k not in t:
            if not create:
                return None
            t[k] = tomlkit.table()
        t = t[k]
    return t


def get_value(doc, p: Parameter) -> np.ndarray | None:
    """The key's whole value in SI (1-D array; a scalar key gives one element); the default when the
    file lacks it, or None when it has no default."""
    t = _node(doc, p.path)
    if t is None or p.path[-1] not in t:
        return None if p.default is None else np.atleast_1d(np.asarray(p.default, float)).copy()
    v = t[p.path[-1]]
    items = list(v) if isinstance(v, list) else [v]
    if p.plain:
        return np.array([float(x) for x in items])
    return np.array([float(u.parse_quantity(str(x), p.dimension)) for x in items])


def _text(p: Parameter, value: float) -> str:
    return f"{value / p.scale:.4g} {p.unit}"


def _item(p: Parameter, value: float):
    """The TOML item of one value: a number for a plain key, else text with its unit."""
    return float(f"{value:.4g}") if p.plain else _text(p, value)


def set_value(doc, p: Parameter, value: np.ndarray, comment: str | None = None) -> None:
    """Write ``value`` (SI, the key's whole value, as :func:`get_value` gives it) into ``doc``
    in the parameter's unit, a list when the file had one (or the value has several
    elements), with ``comment`` after it."""
    t = _node(doc, p.path, create=True)
    key = p.path[-1]
    had_list = key in t and isinstance(t[key], list)
    value = np.atleast_1d(np.asarray(value, float))
    if had_list or len(value) > 1:
        item = tomlkit.array()
        item.extend(_item(p, x) for x in value)
    else:
        item = tomlkit.item(_item(p, float(value[0])))
    if comment:
        item.comment(comment)
    t[key] = item


def moved(p: Parameter, value: np.ndarray, step: float) -> np.ndarray:
    """``value`` moved by one search step (the whole key, or its element ``p.index``), clipped
    to the bounds."""
    v = np.array(value, float)
    if p.index is not None and p.length is not None and v.size == 1:
        v = np.full(p.length, v[0])
    sel = slice(None) if p.index is None else p.index
    if p.kind == "log":
        base = v[sel]
        start = p.lower if p.zero_from is None else p.zero_from
        # a zero key stays zero for a step below one (not the lower bound: the same filter)
        v[sel] = np.where(base > 0, np.clip(base * step, p.lower, p.upper),
                          np.clip(start * step, p.lower, p.upper) if step > 1 else base)
    else:
        v[sel] = np.clip(v[sel] + step, p.lower, p.upper)
    return v
