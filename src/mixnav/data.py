"""In-memory data types shared by the simulator, the readers and the filters.

Plain frozen dataclasses of numpy arrays, validated once when built, so the
filters can trust them. Times are seconds on one time axis (GPS time of week
for real data, seconds since start for simulation).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .attitude import quat_to_euler
from .errors import DataError


#: plausible heights of GNSS fixes [m] and the largest sigma of a fix [m] (docs/validation.md)
HEIGHT_RANGE = (-1000.0, 100e3)
MAX_SIGMA = 1e5


def _check(cond: bool, msg: str, source: str | None) -> None:
    if not cond:
        raise DataError(msg, file=source)


def _finite(name: str, a: np.ndarray, source: str | None) -> None:
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise DataError(f"{name} has a non-finite value at index {tuple(int(i) for i in bad)}", file=source)


@dataclass(frozen=True)
class InitialState:
    """Initial navigation estimate and its 1-sigma uncertainty.

    Attributes
    ----------
    time : float
        [s]; must be the start of the IMU data or later.
    nav : ndarray (10,)
        ``[q_nb(4), v_n(3), lat, lon, h]``.
    sigma_att : ndarray (3,)
        Attitude error sigma as a rotation vector in NED [rad].
    sigma_vel, sigma_pos : ndarray (3,)
        [m/s], NED [m].
    sigma_clock : ndarray (2,)
        Clock bias [m] and drift [m/s] sigma (17-state layout only).
    sensor0 : ndarray (12,) or None
        Initial sensor-error estimates ``[bg, ba, sg, sa]`` (e.g. a gyro bias
        measured at rest); zero when None.
    clock0 : ndarray (2,) or None
        Initial receiver clock bias [m] and drift [m/s] estimates; zero when None.
    aux0 : dict or None
        Initial estimates of auxiliary blocks (name -> array of the block's size,
        e.g. ``{"system_offset": [12.0]}``); zero for a block not named.
    """

    time: float
    nav: np.ndarray
    sigma_att: np.ndarray
    sigma_vel: np.ndarray
    sigma_pos: np.ndarray
    sigma_clock: np.ndarray = field(default_factory=lambda: np.array([10.0, 1.0]))
    sensor0: np.ndarray | None = None
    clock0: np.ndarray | None = None
    aux0: dict | None = None

    def __post_init__(self):
        nav = np.asarray(self.nav, dtype=float)
        if self.clock0 is not None:
            c = np.asarray(self.clock0, dtype=float)
            _check(c.shape == (2,) and np.isfinite(c).all(), f"InitialState.clock0 must be 2 finite numbers "
                   f"(bias [m], drift [m/s]), got {c.tolist()}", None)
        _check(nav.shape == (10,), f"InitialState.nav must be [q_nb(4), v_n(3), lat, lon, h], shape (10,), "
               f"got {nav.shape}", None)
        _finite("InitialState.nav", nav, None)
        _check(abs(np.linalg.norm(nav[0:4]) - 1.0) < 1e-6, "InitialState.nav[0:4] must be a unit quaternion "
               f"(norm {np.linalg.norm(nav[0:4]):.6g})", None)
        _check(abs(nav[7]) <= np.pi / 2 and abs(nav[8]) <= 2 * np.pi,
               f"InitialState.nav latitude/longitude must be in radians, got {nav[7]:.6g}, {nav[8]:.6g}", None)
        for name in ("sigma_att", "sigma_vel", "sigma_pos"):
            a = np.asarray(getattr(self, name), dtype=float)
            _check(a.shape == (3,) and np.all(np.isfinite(a)) and np.all(a >= 0),
                   f"InitialState.{name} must be 3 finite non-negative sigmas, got {a.tolist()}", None)



@dataclass(frozen=True)
class ImuData:
    """IMU angle and velocity increments.

    Attributes
    ----------
    time : ndarray (N,)
        End time of each increment [s], strictly increasing.
    dt : ndarray (N,)
        Length of each increment's interval [s]; the interval is
        ``(time - dt, time]``.
    dtheta : ndarray (N, 3)
        Angle increments in the IMU (body) frame [rad].
    dvel : ndarray (N, 3)
        Velocity increments of specific force in the body frame [m/s].
    source : str or None
        Where the data came from (file name), for error messages.
    gaps : int
        Number of time gaps longer than the reader's limit that were
        accepted with a warning (reported in metrics.json).
    spikes : int
        Number of samples the reader replaced as spikes (reported in metrics.json).
    partial_lines : int
        Partial first or last lines the reader skipped (drive-0708; reported in metrics.json).
    """

    time: np.ndarray
    dt: np.ndarray
    dtheta: np.ndarray
    dvel: np.ndarray
    source: str | None = None
    gaps: int = 0
    spikes: int = 0   # samples replaced by the reader's spike rule (io/imu_checks.check_spikes)
    partial_lines: int = 0   # partial edge lines the reader skipped (drive-0708)

    def __post_init__(self):
        n = len(self.time)
        _check(self.dt.shape == (n,) and self.dtheta.shape == (n, 3) and self.dvel.shape == (n, 3),
               f"IMU arrays disagree in shape: time {self.time.shape}, dt {self.dt.shape}, "
               f"dtheta {self.dtheta.shape}, dvel {self.dvel.shape}", self.source)
        for name in ("time", "dt", "dtheta", "dvel"):
            _finite(name, getattr(self, name), self.source)
        _check(bool(np.all(self.dt > 0)), "IMU dt must be positive", self.source)
        if n > 1:
            bad = np.nonzero(np.diff(self.time) <= 0)[0]
            _check(not len(bad), f"IMU times must increase strictly: sample {bad[0] + 1 if len(bad) else 0} "
                   f"(t = {self.time[bad[0] + 1] if len(bad) else 0:.6f} s) is not after the one before", self.source)

    @property
    def start_time(self) -> float:
        return float(self.time[0] - self.dt[0])

    def __len__(self) -> int:
        return len(self.time)


@dataclass(frozen=True)
class OdometryIncrements(ImuData):
    """Wheel-odometry increments in :class:`~mixnav.data.ImuData`'s arrays, so the engine
    splits them at event times exactly as it splits IMU increments (both are
    integrals over the interval).

    ``dtheta[:, 2]`` is the heading increment [rad] (yaw rate x dt, about the
    vehicle's down axis; the other two columns zero); ``dvel[:, 0]`` is the
    **distance** travelled [m] (speed x dt; not a velocity increment; the other
    two columns zero). Build it with :func:`mixnav.motion.odometry_increments`.
    """


@dataclass(frozen=True)
class GnssFixes:
    """GNSS position (and optionally velocity) fixes of the antenna.

    Attributes
    ----------
    time : ndarray (M,)
        Fix times [s], strictly increasing.
    lla : ndarray (M, 3)
        Latitude, longitude [rad], ellipsoidal height [m].
    pos_sigma : ndarray (M, 3)
        1-sigma position error north, east, down [m].
    vel_n : ndarray (M, 3) or None
        Velocity north, east, down [m/s].
    vel_sigma : ndarray (M, 3) or None
        1-sigma velocity error [m/s].
    """

    time: np.ndarray
    lla: np.ndarray
    pos_sigma: np.ndarray
    vel_n: np.ndarray | None = None
    vel_sigma: np.ndarray | None = None
    source: str | None = None

    def __post_init__(self):
        m = len(self.time)
        _check(self.lla.shape == (m, 3) and self.pos_sigma.shape == (m, 3),
               "GNSS time, lla and pos_sigma disagree in shape", self.source)
        _check((self.vel_n is None) == (self.vel_sigma is None),
               "GNSS velocity and its sigma must be given together", self.source)
        _finite("lla", self.lla, self.source)
        if m:
            lat, lon = np.abs(self.lla[:, 0]).max(), np.abs(self.lla[:, 1]).max()
            _check(lat <= np.pi / 2 and lon <= 2 * np.pi, f"GNSS latitude/longitude must be in radians (largest "
                   f"|lat| {lat:.6g}, |lon| {lon:.6g}: degrees?)", self.source)
        _check(bool(np.all(self.pos_sigma > 0)), "GNSS position sigma must be positive", self.source)
        if m:
            h = self.lla[:, 2]
            k = int(np.argmax((h < HEIGHT_RANGE[0]) | (h > HEIGHT_RANGE[1])))
            _check(HEIGHT_RANGE[0] <= h[k] <= HEIGHT_RANGE[1], f"GNSS height {h[k]:.6g} m at fix {k} "
                   f"(t = {self.time[k]:.3f} s) is outside {HEIGHT_RANGE[0]:g}..{HEIGHT_RANGE[1]:g} m", self.source)
            s = self.pos_sigma
            _check(bool(np.all(s <= MAX_SIGMA)), f"GNSS position sigma {float(s.max()):.6g} m is beyond "
                   f"{MAX_SIGMA:g} m: not a fix", self.source)
        if self.vel_n is not None:
            _check(self.vel_n.shape == (m, 3) and self.vel_sigma.shape == (m, 3),
                   "GNSS velocity arrays disagree in shape", self.source)
            _finite("vel_n", self.vel_n, self.source)
            _check(bool(np.all(self.vel_sigma > 0)), "GNSS velocity sigma must be positive", self.source)
        if m > 1:
            _check(bool(np.all(np.diff(self.time) > 0)), "GNSS times must increase strictly", self.source)

    def __len__(self) -> int:
        return len(self.time)


@dataclass(frozen=True)
class Trajectory:
    """Navigation states over time (truth, reference or solution).

    Attributes
    ----------
    time : ndarray (N,)
    lla : ndarray (N, 3)
        Latitude, longitude [rad], ellipsoidal height [m].
    v_n : ndarray (N, 3) or None
        Velocity north, east, down [m/s]; None when unknown (e.g. a
        position-only reference).
    q_nb : ndarray (N, 4) or None
        Attitude quaternion, body to NED, scalar first; None when unknown.
    """

    time: np.ndarray
    lla: np.ndarray
    v_n: np.ndarray | None
    q_nb: np.ndarray | None
    extra: dict = field(default_factory=dict)

    @property
    def rpy(self) -> np.ndarray | None:
        """Roll, pitch, yaw [rad], shape (N, 3), or None."""
        return None if self.q_nb is None else quat_to_euler(self.q_nb)

    def __len__(self) -> int:
        return len(self.time)


#: Largest plausible land-vehicle speed [m/s] (about 360 km/h): a faster odometer
#: sample is a unit or parsing error, never a measurement.
MAX_VEHICLE_SPEED = 100.0


@dataclass(frozen=True)
class OdometerData:
    """Odometer (wheel-speed) measurements: the forward speed of a wheel point.

    Attributes
    ----------
    time : ndarray (M,)
        Sample times [s], strictly increasing, on the IMU time axis.
    speed : ndarray (M,)
        Forward speed [m/s] along the vehicle's x axis, >= 0 unless ``signed``
        (an unsigned wheel-speed sensor cannot say it reverses), below
        :data:`MAX_VEHICLE_SPEED`.
    sigma : ndarray (M,)
        1-sigma noise of each sample [m/s], positive.
    signed : bool
        The speed may be negative (reversing).
    source : str or None
        File the samples came from (named in errors).
    gaps : int
        Number of time gaps longer than the reader's limit that were
        accepted with a warning (as :attr:`ImuData.gaps`; reported in
        metrics.json).
    """

    time: np.ndarray
    speed: np.ndarray
    sigma: np.ndarray
    signed: bool = False
    source: str | None = None
    gaps: int = 0

    def __post_init__(self):
        m = len(self.time)
        _check(np.shape(self.speed) == (m,) and np.shape(self.sigma) == (m,),
               f"odometer time, speed and sigma disagree in shape ({m}, {np.shape(self.speed)}, "
               f"{np.shape(self.sigma)})", self.source)
        _finite("odometer time", self.time, self.source)
        _finite("odometer speed", self.speed, self.source)
        if m:
            if not self.signed and self.speed.min() < 0:
                i = int(np.argmin(self.speed))
                raise DataError(f"odometer speed is negative ({self.speed[i]:.6g} m/s at sample {i}, "
                                f"t = {self.time[i]:.3f} s); give signed speeds as signed", file=self.source)
            big = np.abs(self.speed) > MAX_VEHICLE_SPEED
            if big.any():
                i = int(np.argmax(big))
                raise DataError(f"odometer speed {self.speed[i]:.6g} m/s at sample {i} (t = {self.time[i]:.3f} s) "
                                f"is above {MAX_VEHICLE_SPEED:g} m/s: wrong unit (km/h? mm/s?)", file=self.source)
            _check(bool(np.all(self.sigma > 0)) and bool(np.all(np.isfinite(self.sigma))),
                   "odometer sigma must be finite and positive", self.source)
        if m > 1:
            d = np.diff(self.time)
            if not np.all(d > 0):
                i = int(np.argmax(~(d > 0)))
                raise DataError(f"odometer times must increase strictly: sample {i + 1} (t = {self.time[i + 1]:.6f} s)"
                                f" is not after sample {i} (t = {self.time[i]:.6f} s)", file=self.source)

    def __len__(self) -> int:
        return len(self.time)


#: RINEX system letters a raw-GNSS record may hold (mixnav.gnss.signals.SYSTEMS names them)
GNSS_SYSTEMS = ("G", "R", "E", "C", "J")
#: the letters corrected pseudoranges may hold besides: ``S`` SBAS (a smartLoc log's system 2),
#: positioned from the satellite positions the source gives, so no broadcast orbit is needed
CORRECTED_SYSTEMS = GNSS_SYSTEMS + ("S",)
#: columns of RawPseudoranges.lli: the observation each loss-of-lock indicator belongs to
LLI_COLUMNS = ("pseudorange", "carrier", "doppler", "cn0")
#: GLONASS frequency channel numbers (inclusive), and the value of a row without one
GLONASS_CHANNELS = (-7, 6)
NO_CHANNEL = -128


@dataclass(frozen=True, eq=False)
class RawPseudoranges:
    """Receiver pseudoranges grouped by epoch: what every raw-GNSS reader returns (Android
    GnssLogger logs, RINEX observation files, u-blox logs, smartLoc logs).

    Two forms, told apart by ``corrected``: broadcast pseudoranges (``corrected = False``), the
    satellite clock and atmosphere still to apply from a navigation file, what
    :func:`mixnav.gnss.spp.solve_epochs` reads; and corrected ones (``corrected = True``: a
    smartLoc log), the satellite clock and atmosphere already removed by the source and each
    row's satellite position (``sat_ecef``) and variance given, so the satellite-state and
    correction step is skipped (:meth:`mixnav.gnss.pseudoranges.PseudorangeEpochs.from_raw`
    groups them for :mod:`mixnav.gnss.corrected_spp` and the filters). Corrected logs have no
    GPS time: ``week`` is 0 and ``tow`` the log's own seconds.

    Attributes
    ----------
    week : ndarray of int (k,)
        GPS week of each epoch.
    tow : ndarray (k,)
        Receive time of each epoch, GPS seconds of week [s].
    epoch : ndarray of int (m,)
        Epoch index of each measurement.
    prn : ndarray of int (m,)
    pseudorange : ndarray (m,)
        [m].
    rejected : dict
        Measurements left out by the reader, per reason.
    epochs_all_rejected : int
        Epochs whose every measurement was rejected (absent from the arrays; counted by the SPP).
    source : str
        File(s) read.
    cn0 : ndarray (m,) or None
        Carrier-to-noise density [dB-Hz], when the format gives it (Android).
    doppler : ndarray (m,) or None
        L1 Doppler [Hz] (NaN where blank), when the format gives it (RINEX ``D1C``/``D1``);
        positive for an approaching satellite: the range rate is ``-lambda_L1 * doppler``.
    sigma : ndarray (m,) or None
        The receiver's own pseudorange sigma [m] (Android ``ReceivedSvTimeUncertaintyNanos``).
    time_nanos : ndarray of int (k,) or None
        The receiver's hardware clock of each epoch [ns] (Android ``TimeNanos``).
    code : str
        The observation code read (RINEX: ``C1C`` or ``C1``).
    version : float
        The file's format version (RINEX).
    event_records : dict
        Records skipped because they are not observations, per epoch flag (RINEX), or per
        message type (u-blox logs: ``NAV-PVT``, ``NMEA``..., and ``bytes skipped``).
    system : ndarray of str (m,) or None
        RINEX system letter of each measurement (``G`` GPS, ``R`` GLONASS, ``E`` Galileo,
        ``C`` BeiDou, ``J`` QZSS); ``prn`` is then the satellite number within its system
        (``R12``: slot 12). None: every measurement is GPS (what readers of GPS alone give).
    signal : ndarray of str (m,) or None
        The observation code each pseudorange was read from (RINEX: ``C1C``, ``C1X``, ``C2I``,
        ``C1``, ``P1``); the carrier, Doppler and C/N0 are those of the same signal.
    carrier : ndarray (m,) or None
        Carrier phase [cycles] (NaN where blank), when the format gives it (RINEX ``L1C``...).
    lli : ndarray of int8 (m, 4) or None
        RINEX loss-of-lock indicators of the pseudorange, carrier, Doppler and C/N0 values
        (columns :data:`LLI_COLUMNS`; 0 where blank): bit 0 a possible cycle slip, bit 1
        half-cycle ambiguity, bit 2 (RINEX 3) BOC tracking / (RINEX 2) anti-spoofing.
    line : ndarray of int (m,) or None
        1-based line of each measurement's satellite record in ``source`` (RINEX).
    glonass_channels : dict
        GLONASS slot -> frequency channel number k (-7..+6; carrier frequency
        ``1602 + 0.5625 k`` MHz on L1): the observation header's ``GLONASS SLOT / FRQ #``,
        or attached from a navigation file (:meth:`with_glonass_channels`); a u-blox log's
        ``freqId - 7`` (:mod:`mixnav.io.ubx`).
    leap_seconds : ndarray (k,) or None
        GPS - UTC [s] the receiver gave at each epoch (u-blox RXM-RAWX ``leapS``; NaN where
        the receiver had not determined it yet), when the format gives it.
    corrected : bool
        The pseudoranges have the satellite clock and atmosphere removed already and
        ``sat_ecef`` and ``variance`` are given (a smartLoc log); then ``system`` may also
        hold ``S`` (SBAS, :data:`CORRECTED_SYSTEMS`).
    sat_ecef : ndarray (m, 3) or None
        Satellite position at the transmit time, in the ECEF frame of that time [m], as the
        source gives it (corrected pseudoranges only).
    variance : ndarray (m,) or None
        The source's pseudorange variance [m^2] (> 0; corrected pseudoranges only).
    elevation : ndarray (m,) or None
        Satellite elevation [rad] as the source gives it (corrected pseudoranges only).
    """

    week: np.ndarray
    tow: np.ndarray
    epoch: np.ndarray
    prn: np.ndarray
    pseudorange: np.ndarray
    rejected: dict = field(default_factory=dict)
    epochs_all_rejected: int = 0
    source: str = ""
    cn0: np.ndarray | None = None
    doppler: np.ndarray | None = None
    sigma: np.ndarray | None = None
    time_nanos: np.ndarray | None = None
    code: str = ""
    version: float = 0.0
    event_records: dict = field(default_factory=dict)
    system: np.ndarray | None = None
    signal: np.ndarray | None = None
    carrier: np.ndarray | None = None
    lli: np.ndarray | None = None
    line: np.ndarray | None = None
    glonass_channels: dict = field(default_factory=dict)
    leap_seconds: np.ndarray | None = None
    corrected: bool = False
    sat_ecef: np.ndarray | None = None
    variance: np.ndarray | None = None
    elevation: np.ndarray | None = None

    def __post_init__(self):
        m = len(self.prn)
        if self.corrected:
            _check(self.sat_ecef is not None and self.variance is not None,
                   "corrected pseudoranges need each row's satellite position (sat_ecef) and variance", self.source)
        else:
            given = [n for n in ("sat_ecef", "variance", "elevation") if getattr(self, n) is not None]
            _check(not given, f"{', '.join(given)} given for broadcast pseudoranges: only corrected ones "
                   "(corrected=True) carry them", self.source)
        _check(self.sat_ecef is None or np.shape(self.sat_ecef) == (m, 3),
               f"sat_ecef has shape {np.shape(self.sat_ecef)}, expected ({m}, 3)", self.source)
        for name in ("variance", "elevation"):
            a = getattr(self, name)
            _check(a is None or np.shape(a) == (m,), f"{name} has shape {np.shape(a)}, expected ({m},)", self.source)
        _check(self.variance is None or bool(np.all(self.variance > 0)), "variances must be positive", self.source)
        _check(self.leap_seconds is None or np.shape(self.leap_seconds) == (len(self.tow),),
               f"leap_seconds has shape {np.shape(self.leap_seconds)}, expected ({len(self.tow)},)", self.source)
        for name in ("system", "signal", "carrier", "line"):
            a = getattr(self, name)
            _check(a is None or np.shape(a) == (m,), f"{name} has shape {np.shape(a)}, expected ({m},)", self.source)
        _check(self.lli is None or np.shape(self.lli) == (m, len(LLI_COLUMNS)),
               f"lli has shape {np.shape(self.lli)}, expected ({m}, {len(LLI_COLUMNS)})", self.source)
        if self.system is not None and m:
            allowed = CORRECTED_SYSTEMS if self.corrected else GNSS_SYSTEMS
            bad = sorted(set(np.unique(self.system).tolist()) - set(allowed))
            _check(not bad, f"system letters {bad} are not among {', '.join(allowed)}", self.source)
        for slot, k in self.glonass_channels.items():
            _check(GLONASS_CHANNELS[0] <= int(k) <= GLONASS_CHANNELS[1],
                   f"GLONASS slot {slot}: frequency channel {k} is outside {GLONASS_CHANNELS[0]}..{GLONASS_CHANNELS[1]}",
                   self.source)

    def __len__(self) -> int:
        return len(self.tow)

    def systems(self) -> np.ndarray:
        """The system letter of each measurement ((m,) str; ``G`` for every row when
        ``system`` is None)."""
        return np.full(len(self.prn), "G") if self.system is None else np.asarray(self.system)

    def satellite_ids(self) -> np.ndarray:
        """RINEX satellite names of the measurements ((m,) str: ``G05``, ``R12``)."""
        return np.char.add(self.systems().astype("<U1"), np.char.zfill(np.asarray(self.prn).astype(str), 2))

    def keep_systems(self, systems) -> RawPseudoranges:
        """A copy with the measurements of the system letters ``systems`` alone; the others are
        left out and counted in ``rejected`` (``system not read: <letter>``, as the RINEX
        reader counts them), and epochs left without a measurement are dropped and counted in
        ``epochs_all_rejected``. ``self`` when every row is kept."""
        from dataclasses import replace
        letters = self.systems()
        keep = np.isin(letters, list(systems))
        if keep.all():
            return self
        rejected = dict(self.rejected)
        for s, n in zip(*np.unique(letters[~keep], return_counts=True)):
            rejected[f"system not read: {s}"] = rejected.get(f"system not read: {s}", 0) + int(n)
        used, epoch = np.unique(np.asarray(self.epoch)[keep], return_inverse=True)
        per_row = {n: getattr(self, n)[keep] for n in ("prn", "pseudorange", "cn0", "doppler", "sigma", "system",
                                                        "signal", "carrier", "lli", "line", "sat_ecef", "variance",
                                                        "elevation") if getattr(self, n) is not None}
        per_epoch = {n: getattr(self, n)[used] for n in ("week", "tow", "time_nanos", "leap_seconds")
                     if getattr(self, n) is not None}
        return replace(self, epoch=epoch.astype(np.int64), rejected=rejected,
                       epochs_all_rejected=self.epochs_all_rejected + len(self.tow) - len(used), **per_row, **per_epoch)

    def with_glonass_channels(self, channels: dict) -> RawPseudoranges:
        """A copy with the GLONASS frequency channels ``channels`` (slot -> k, e.g. from the
        navigation file's records) added to those the observation header gave. A slot both
        give with different numbers is a DataError naming ``source``."""
        from dataclasses import replace
        merged = dict(self.glonass_channels)
        for slot, k in channels.items():
            slot, k = int(slot), int(k)
            if slot in merged and merged[slot] != k:
                raise DataError(f"GLONASS slot {slot}: frequency channel {k} given, but the observation header "
                                f"gives {merged[slot]}", file=self.source)
            merged[slot] = k
        return replace(self, glonass_channels=dict(sorted(merged.items())))

    def glonass_channel(self) -> np.ndarray:
        """Frequency channel k of each measurement ((m,) int: GLONASS rows their slot's,
        :data:`NO_CHANNEL` for other systems and for slots without one)."""
        out = np.full(len(self.prn), NO_CHANNEL, dtype=np.int64)
        glo = self.systems() == "R"
        for slot, k in self.glonass_channels.items():
            out[glo & (np.asarray(self.prn) == slot)] = k
        return out

    def check_glonass_channels(self) -> None:
        """Raise DataError (naming ``source`` and the line of the first such record, when
        known) if a GLONASS measurement's slot has no frequency channel number: what a
        user of GLONASS carrier phase or Doppler (wavelength per channel) needs first."""
        missing = (self.systems() == "R") & (self.glonass_channel() == NO_CHANNEL)
        if missing.any():
            i = int(np.flatnonzero(missing)[0])
            slots = sorted(set(np.asarray(self.prn)[missing].tolist()))
            raise DataError(f"GLONASS slots {', '.join(f'R{s:02d}' for s in slots)} have no frequency channel number "
                            "(the observation header has no 'GLONASS SLOT / FRQ #' entry for them: attach the "
                            "navigation file's with with_glonass_channels)", file=self.source,
                            line=None if self.line is None else int(self.line[i]))


@dataclass(frozen=True)
class WheelOdometry:
    """Forward speed and yaw rate of a vehicle (what an odometry reader returns; the
    dead-reckoning model's input, :func:`mixnav.motion.dead_reckoning.odometry_increments`).

    Attributes
    ----------
    time : ndarray (k,)
        [s], strictly increasing.
    speed, yaw_rate : ndarray (k,)
        Forward velocity [m/s] and turn rate about the vehicle's z axis [rad/s], with the
        sign the file gives (the dataset's ``yaw_rate_axis`` says which way is positive).
    speed_var, yaw_rate_var : ndarray (k,)
        Their variances [m^2/s^2], [rad^2/s^2].
    line : ndarray of int (k,)
        1-based line of each sample in the file.
    path : str
    """

    time: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    speed_var: np.ndarray
    yaw_rate_var: np.ndarray
    line: np.ndarray
    path: str = ""

    def __len__(self) -> int:
        return int(self.time.size)
