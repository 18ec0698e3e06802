"""Reader of the smartLoc data set (TU Chemnitz) and pseudorange residuals against its ground truth.

The files
---------
Text, one measurement a line, whitespace-separated, the first token names
the row type (see the data set's ``readme.txt``):

``pseudorange3`` (``*_Input.txt``), 11 tokens
    time [s], pseudorange [m] (satellite clock and atmosphere already
    removed), its variance [m^2], satellite ECEF x, y, z [m], satellite id,
    system (1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo, 16 QZSS, 32 BeiDou),
    elevation [deg], C/N0 [dB-Hz]. Several rows share an epoch time.
``odom3`` (``*_Input.txt``), 14 tokens
    time [s], velocity x, y, z [m/s], turn rate x, y, z [rad/s] (vehicle frame),
    then the six variances; :func:`read_odometry` keeps the forward speed, the
    yaw rate (turn rate about z) and their variances. A speed beyond
    ``MAX_SPEED`` (100 m/s, or backwards beyond 10 m/s), a yaw rate beyond
    ``MAX_YAW_RATE`` (3 rad/s: a car turns at most about 1 rad/s; this catches
    deg/s) or a non-positive variance is an error naming the line.
``point3`` (``*_GT.txt``), 14 tokens
    time [s], ECEF x, y, z of the reference [m], a 3x3 covariance (zeros).

Validation (every failure is a :class:`~mixnav.errors.DataError` naming the
file and the 1-based line): token count (an empty field, e.g. a NaN written as nothing,
named by its column), numbers (finite, named by their column), an unknown row
type, time going backwards (pseudoranges: non-decreasing; ground truth:
strictly increasing), a repeated (time, system, satellite), a non-integer
satellite id or unknown system code, a non-positive variance, an elevation
outside [-90, 90] deg, a satellite farther than 1e7..5e7 m from the Earth's
centre, a ground-truth point farther than 6.2e6..6.5e6 m from it.

Residuals against the ground truth
----------------------------------
:func:`pseudorange_residuals` computes per pseudorange::

    raw_i  = rho_i - | R3(OMEGA_E tau_i) s_i - r(t_i) |,   tau_i = |R3(OMEGA_E tau_i) s_i - r(t_i)| / c
    res_i  = raw_i - b_i,    b_i = location of {raw_j : j in the epoch and system of i, j != i}

- ``r(t)``: the ground-truth position, linearly interpolated in ECEF to the
  pseudorange time (in smartLoc the two share the time stamps, so the
  interpolation is exact there); pseudoranges outside the truth's time span
  are excluded and counted.
- Earth rotation (Sagnac): the data set's satellite positions are those at
  the transmit time, in the ECEF frame of that time, so they are turned by
  ``OMEGA_E tau`` into the frame of the reception time
  (:func:`mixnav.gnss.geometry.earth_rotation_correction`), tau solved by a
  fixed-point iteration (3 steps; converged to < 1e-9 m). The readme does not
  say it; the residuals do: on Berlin Potsdamer Platz the robust spread
  (1.4826 MAD) of the residuals is 23.5 m with the rotation, 30.8 m without
  (15.4 / 22.4 m with the plain median clock below); the wrong sign is worse
  still (``benchmarks/results/smartloc_residuals.md``).
- ``b_i``: the receiver clock (and, by taking it per system, the GLONASS-GPS
  inter-system bias), estimated per epoch and system as the **median**
  (``clock="median"``, the default) or a Huber M-estimate of location
  (``clock="huber"``: k = 1.345 times the scaled MAD, iteratively
  reweighted). A plain mean would absorb the non-line-of-sight (NLOS)
  errors, which are large and positive: one 100 m NLOS range in an epoch of
  8 would move the mean by 12.5 m and every other residual by -12.5 m. The
  median is not moved by one outlier; where several satellites of an epoch
  are NLOS it still shifts by a few metres, so line-of-sight satellites get
  negative residuals (the 85 deg GPS satellite 12 has a median residual of
  -12 m).
- **Leave one out** (``leave_one_out=True``, the default): the clock removed
  from satellite i is estimated from the *other* satellites of its group.
  With the group's own median (``leave_one_out=False``; ``clock_bias``
  always holds that one) the median satellite of every odd-sized group has
  a residual of exactly zero (7.8 % of the Berlin residuals) and all
  residuals are pulled towards zero, a spike that a mixture fit takes for a
  narrow component (weight 0.13, sigma 1.2 m on Berlin). Leave-one-out
  residuals are the satellite's error minus an estimate independent of it:
  no spike, no shrinkage, a little wider.
- Groups with fewer than ``min_satellites`` (default 3, counting satellite
  i) are left out (NaN, counted): with one satellite there is no clock,
  with two the residuals are +-their difference.

Residuals per satellite form channels: :meth:`SmartlocResiduals.channels`
gives an (n_epochs, n_satellites) array with NaN where a satellite is not
tracked (or its group was left out).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data import RawPseudoranges, Trajectory, WheelOdometry
from ..errors import DataError
from ..gnss.geometry import C_LIGHT, earth_rotation_correction
from .registry import ReadOptions, register_reader
from .tables import check_times

__all__ = [
    "SYSTEMS", "SmartlocPseudoranges", "SmartlocTruth", "SmartlocResiduals", "read_pseudoranges",
    "read_ground_truth", "read_smartloc", "SmartlocOdometry", "read_odometry", "to_raw_pseudoranges",
    "to_pseudorange_epochs", "geometric_range", "clock_per_epoch", "pseudorange_residuals",
]

#: smartLoc system code -> one-letter RINEX system identifier
SYSTEMS = {1: "G", 2: "S", 4: "R", 8: "E", 16: "J", 32: "C"}
_KNOWN_TAGS = ("pseudorange3", "odom3", "point3")
_NTOK = {"pseudorange3": 11, "odom3": 14, "point3": 14}
_SAT_RADIUS = (1.0e7, 5.0e7)     # [m] GNSS orbits: 2.0e7 (GLONASS) .. 4.2e7 (GEO)
_RX_RADIUS = (6.2e6, 6.5e6)      # [m] near the Earth's surface
_HUBER_K = 1.345
MAX_SPEED = 100.0                # [m/s] forward; backwards at most 10 m/s
MAX_YAW_RATE = 3.0               # [rad/s]


@dataclass(frozen=True)
class SmartlocPseudoranges:
    """The ``pseudorange3`` rows of a smartLoc input file, in file order.

    Attributes
    ----------
    time : ndarray (n,)
        [s], non-decreasing; rows of one epoch share it.
    pseudorange : ndarray (n,)
        [m], satellite clock and atmosphere removed (receiver clock not).
    variance : ndarray (n,)
        The data set's pseudorange variance [m^2].
    sat_ecef : ndarray (n, 3)
        Satellite position at the transmit time, ECEF of that time [m].
    sat_id : ndarray of int (n,)
        Satellite number as in the file (GLONASS as 3xx).
    system : ndarray of int (n,)
        System code (see :data:`SYSTEMS`).
    elevation : ndarray (n,)
        [rad] (the file's degrees converted here).
    cn0 : ndarray (n,)
        [dB-Hz].
    line : ndarray of int (n,)
        1-based line of each row in the file.
    path : str
    """

    time: np.ndarray
    pseudorange: np.ndarray
    variance: np.ndarray
    sat_ecef: np.ndarray
    sat_id: np.ndarray
    system: np.ndarray
    elevation: np.ndarray
    cn0: np.ndarray
    line: np.ndarray
    path: str = ""

    def __len__(self) -> int:
        return int(self.time.size)

    @property
    def epoch_times(self) -> np.ndarray:
        """Distinct epoch times (n_epochs,) [s], increasing."""
        return np.unique(self.time)

    @property
    def epoch_index(self) -> np.ndarray:
        """Index into :attr:`epoch_times` of each row, (n,)."""
        return np.searchsorted(self.epoch_times, self.time)

    @property
    def labels(self) -> list[str]:
        """``"G12"``, ``"R301"``, ... of each row."""
        return [f"{SYSTEMS[int(s)]}{int(i):02d}" for s, i in zip(self.system, self.sat_id)]


@dataclass(frozen=True)
class SmartlocTruth:
    """The ``point3`` rows of a smartLoc ground-truth file.

    Attributes
    ----------
    time : ndarray (m,)
        [s], strictly increasing.
    pos_ecef : ndarray (m, 3)
        Reference position [m].
    line : ndarray of int (m,)
    path : str
    """

    time: np.ndarray
    pos_ecef: np.ndarray
    line: np.ndarray
    path: str = ""

    def __len__(self) -> int:
        return int(self.time.size)

    def covers(self, t) -> np.ndarray:
        """bool (k,): times inside ``[time[0], time[-1]]``."""
        t = np.asarray(t, dtype=float)
        return (t >= self.time[0]) & (t <= self.time[-1])

    def position_at(self, t) -> np.ndarray:
        """Position at times ``t`` (k,) [s], linear interpolation in ECEF, (k, 3) [m].

        Raises
        ------
        ValueError
            A time outside the truth's span (no extrapolation).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = ~self.covers(t)
        if out.any():
            raise ValueError(f"{int(out.sum())} time(s) outside the ground truth's span "
                             f"[{self.time[0]:g}, {self.time[-1]:g}] s, e.g. {t[out][0]:g} s")
        return np.stack([np.interp(t, self.time, self.pos_ecef[:, k]) for k in range(3)], axis=-1)


#: the ``odom3`` rows of a smartLoc input file: the one odometry type (mixnav.data.WheelOdometry;
#: smartLoc's yaw rate is about z up, positive to the left)
SmartlocOdometry = WheelOdometry


# ---------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------
def _rows(path: Path, tag: str, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Numbers (after the tag) of every ``tag`` row and their 1-based lines."""
    if not path.is_file():
        raise DataError(f"smartLoc {what} file not found", file=str(path))
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise DataError(f"cannot read: {exc}", file=str(path)) from None
    rows, lines = [], []
    ntok = _NTOK[tag]
    for lineno, raw in enumerate(text.splitlines(), start=1):
        toks = raw.split()
        if not toks or toks[0].startswith("#"):
            continue
        if toks[0] not in _KNOWN_TAGS:
            raise DataError(f"unknown row type {toks[0][:30]!r} (expected one of {', '.join(_KNOWN_TAGS)})",
                            file=str(path), line=lineno)
        if toks[0] != tag:
            continue
        if len(toks) != ntok:
            # an empty field (two separators in a row) is a value written as nothing: what a
            # writer makes of a NaN (pandas' default); name its column, not the field count
            fields = re.split(r"[ \t]", raw.strip())
            if "" in fields and len(toks) < ntok:
                k = fields.index("") + 1
                raise DataError(f"column {k} is empty: a missing or non-finite value (a NaN written as nothing); "
                                f"a {tag} row has {ntok} fields, found {len(toks)}", file=str(path), line=lineno)
            raise DataError(f"a {tag} row has {ntok} fields, found {len(toks)}", file=str(path), line=lineno)
        vals = []
        for k, t in enumerate(toks[1:], start=2):
            try:
                v = float(t)
            except ValueError:
                raise DataError(f"column {k}: {t[:30]!r} is not a number", file=str(path), line=lineno) from None
            if not math.isfinite(v):
                raise DataError(f"column {k}: {t!r} is not finite", file=str(path), line=lineno)
            vals.append(v)
        rows.append(vals)
        lines.append(lineno)
    if not rows:
        raise DataError(f"no '{tag}' rows (is this a smartLoc {what} file?)", file=str(path))
    return np.array(rows, dtype=float), np.array(lines, dtype=int)


def _fail_at(mask: np.ndarray, lines: np.ndarray, path: Path, message: str) -> None:
    bad = np.flatnonzero(mask)
    if bad.size:
        more = f" ({bad.size} such rows)" if bad.size > 1 else ""
        raise DataError(message + more, file=str(path), line=int(lines[bad[0]]))


def read_pseudoranges(path) -> SmartlocPseudoranges:
    """Read the ``pseudorange3`` rows of a smartLoc ``*_Input.txt`` file.

    Parameters
    ----------
    path : str or PathLike

    Returns
    -------
    SmartlocPseudoranges

    Raises
    ------
    DataError
        Missing file, no ``pseudorange3`` row, or a malformed row (see the
        module docstring), naming the file and the line.
    """
    path = Path(path)
    a, lines = _rows(path, "pseudorange3", "input")
    t = a[:, 0]
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise DataError(f"pseudorange time goes backwards ({float(t[k - 1])!r} then {float(t[k])!r})", file=str(path),
                        line=int(lines[k]))
    _fail_at(~(a[:, 2] > 0), lines, path, "pseudorange variance (column 4) must be positive")
    _fail_at(~(a[:, 1] > 0), lines, path, "pseudorange (column 3) must be positive")
    r = np.linalg.norm(a[:, 3:6], axis=1)
    _fail_at((r < _SAT_RADIUS[0]) | (r > _SAT_RADIUS[1]), lines, path,
             f"satellite position (columns 5-7) is not {_SAT_RADIUS[0]:.0e}..{_SAT_RADIUS[1]:.0e} m "
             "from the Earth's centre")
    _fail_at(a[:, 6] != np.round(a[:, 6]), lines, path, "satellite id (column 8) is not an integer")
    _fail_at(~np.isin(a[:, 7], list(SYSTEMS)), lines, path,
             f"unknown satellite system code (column 9); known: {', '.join(f'{k}={v}' for k, v in SYSTEMS.items())}")
    _fail_at(np.abs(a[:, 8]) > 90, lines, path, "elevation (column 10) outside [-90, 90] deg")
    sat_id, system = a[:, 6].astype(int), a[:, 7].astype(int)
    # one row per (time, system, satellite)
    order = np.lexsort((sat_id, system, t))
    same = ((t[order][1:] == t[order][:-1]) & (system[order][1:] == system[order][:-1])
            & (sat_id[order][1:] == sat_id[order][:-1]))
    if same.any():
        k = int(order[1:][np.flatnonzero(same)[0]])
        raise DataError(f"satellite {SYSTEMS[int(system[k])]}{int(sat_id[k]):02d} appears twice at time "
                        f"{float(t[k])!r}", file=str(path), line=int(lines[k]))
    return SmartlocPseudoranges(time=t, pseudorange=a[:, 1], variance=a[:, 2],
                                sat_ecef=np.ascontiguousarray(a[:, 3:6]), sat_id=sat_id, system=system,
                                elevation=np.deg2rad(a[:, 8]), cn0=a[:, 9], line=lines, path=str(path))


def read_odometry(path) -> SmartlocOdometry:
    """Read the ``odom3`` rows of a smartLoc ``*_Input.txt`` file.

    Raises
    ------
    DataError
        Missing file, no ``odom3`` row, a malformed row, time not strictly
        increasing, an absurd speed or yaw rate, a non-positive variance (file
        and line named).
    """
    path = Path(path)
    a, lines = _rows(path, "odom3", "input")
    check_times(a[:, 0], lines, str(path), what="odometry")
    _fail_at((a[:, 1] > MAX_SPEED) | (a[:, 1] < -10.0), lines, path,
             f"forward speed (column 3) outside [-10, {MAX_SPEED:g}] m/s")
    _fail_at(np.abs(a[:, 6]) > MAX_YAW_RATE, lines, path,
             f"yaw rate (column 8) beyond {MAX_YAW_RATE:g} rad/s (degrees per second instead of radians?)")
    _fail_at(~((a[:, 7] > 0) & (a[:, 12] > 0)), lines, path,
             "the speed and yaw-rate variances (columns 9 and 14) must be positive")
    return SmartlocOdometry(time=a[:, 0], speed=a[:, 1], yaw_rate=a[:, 6], speed_var=a[:, 7],
                            yaw_rate_var=a[:, 12], line=lines, path=str(path))


def to_raw_pseudoranges(pr: SmartlocPseudoranges) -> RawPseudoranges:
    """The pseudoranges as the one raw-GNSS type, :class:`~mixnav.data.RawPseudoranges`,
    corrected (``corrected = True``: satellite clock and atmosphere removed, each row's
    satellite position, variance and elevation given), in file order; the log has no GPS
    time, so ``week`` is 0 and ``tow`` the log's seconds; system letters from
    :data:`SYSTEMS`, ``prn`` the file's satellite id, ``line`` each row's line."""
    tow, epoch = np.unique(pr.time, return_inverse=True)
    return RawPseudoranges(week=np.zeros(len(tow), dtype=np.int64), tow=tow, epoch=epoch.astype(np.int64),
                           prn=pr.sat_id, pseudorange=pr.pseudorange, source=pr.path, cn0=pr.cn0,
                           system=np.array([SYSTEMS[int(k)] for k in pr.system]), line=pr.line, corrected=True,
                           sat_ecef=pr.sat_ecef, variance=pr.variance, elevation=pr.elevation)


def to_pseudorange_epochs(pr: SmartlocPseudoranges):
    """The pseudoranges as :class:`~mixnav.gnss.pseudoranges.PseudorangeEpochs` (rows grouped
    by time, file order kept inside an epoch): ``PseudorangeEpochs.from_raw`` of
    :func:`to_raw_pseudoranges`."""
    from ..gnss.pseudoranges import PseudorangeEpochs
    return PseudorangeEpochs.from_raw(to_raw_pseudoranges(pr))


def read_ground_truth(path) -> SmartlocTruth:
    """Read the ``point3`` rows of a smartLoc ``*_GT.txt`` file.

    Raises
    ------
    DataError
        Missing file, no ``point3`` row, a malformed row, time not strictly
        increasing, a point not near the Earth's surface (file and line named).
    """
    path = Path(path)
    a, lines = _rows(path, "point3", "ground-truth")
    check_times(a[:, 0], lines, str(path), what="ground-truth")
    r = np.linalg.norm(a[:, 1:4], axis=1)
    _fail_at((r < _RX_RADIUS[0]) | (r > _RX_RADIUS[1]), lines, path,
             f"ground-truth position (columns 3-5) is not {_RX_RADIUS[0]:.2e}..{_RX_RADIUS[1]:.2e} m from the "
             "Earth's centre")
    return SmartlocTruth(time=a[:, 0], pos_ecef=np.ascontiguousarray(a[:, 1:4]), line=lines, path=str(path))


def read_smartloc(folder, name: str = "Berlin_Potsdamer_Platz") -> tuple[SmartlocPseudoranges, SmartlocTruth]:
    """Read ``<folder>/<name>_Input.txt`` (pseudoranges) and ``<name>_GT.txt`` (truth)."""
    folder = Path(folder)
    return read_pseudoranges(folder / f"{name}_Input.txt"), read_ground_truth(folder / f"{name}_GT.txt")


# ---------------------------------------------------------------------------
# residuals
# ---------------------------------------------------------------------------
def geometric_range(rx_ecef, sat_ecef, earth_rotation: bool = True, iterations: int = 3) -> np.ndarray:
    """Receiver-satellite range [m] at the reception time.

    Parameters
    ----------
    rx_ecef : ndarray (n, 3)
        Receiver at the reception time [m].
    sat_ecef : ndarray (n, 3)
        Satellite at the transmit time, in the ECEF frame of the transmit time [m].
    earth_rotation : bool, default True
        Turn the satellite into the reception-time frame by ``OMEGA_E tau``
        with ``tau = range / c`` (fixed point; each step gains a factor
        ``OMEGA_E |s| / c`` ~ 6e-6, so 3 steps reach far below a micrometre).
        False: the plain distance ``|s - r|``.
    iterations : int, default 3

    Returns
    -------
    ndarray (n,)
    """
    rx = np.asarray(rx_ecef, dtype=float)
    sat = np.asarray(sat_ecef, dtype=float)
    rng = np.linalg.norm(sat - rx, axis=-1)
    if not earth_rotation:
        return rng
    for _ in range(iterations):
        rng = np.linalg.norm(earth_rotation_correction(sat, rng / C_LIGHT) - rx, axis=-1)
    return rng


def _huber_location(v: np.ndarray, k: float = _HUBER_K, tol: float = 1e-6, max_iter: int = 50) -> float:
    """Huber M-estimate of location, scale = 1.4826 MAD (median if the MAD is 0)."""
    mu = float(np.median(v))
    s = 1.4826 * float(np.median(np.abs(v - mu)))
    if not s > 0:
        return mu
    for _ in range(max_iter):
        u = np.abs(v - mu) / (k * s)
        w = np.where(u <= 1.0, 1.0, 1.0 / np.maximum(u, 1e-300))
        new = float(np.sum(w * v) / np.sum(w))
        if abs(new - mu) < tol:
            return new
        mu = new
    return mu


def clock_per_epoch(raw, epoch, system, n_epochs: int | None = None, method: str = "median",
                    min_satellites: int = 3, leave_one_out: bool = False):
    """Receiver clock (+ inter-system bias) per epoch and system from range residuals.

    Parameters
    ----------
    raw : ndarray (n,)
        Pseudorange minus geometric range [m].
    epoch : ndarray of int (n,)
        Epoch index of each row (0 .. n_epochs-1).
    system : ndarray of int (n,)
        System code of each row.
    n_epochs : int, optional
        Default ``epoch.max() + 1``.
    method : {"median", "huber"}
        Location estimate of each (epoch, system) group (see the module docstring).
    min_satellites : int, default 3
        Smaller groups (counting every satellite of the group) get no clock (NaN).
    leave_one_out : bool, default False
        The clock removed from a row is the estimate from the *other*
        satellites of its group (see the module docstring).

    Returns
    -------
    bias : ndarray (n_epochs, s)
        Estimate from all satellites of each group [m], NaN where a group is
        absent or too small.
    systems : ndarray of int (s,)
        The system code of each column, increasing.
    count : ndarray of int (n_epochs, s)
        Satellites in each group.
    per_row : ndarray (n,)
        The clock to remove from each row [m]: ``bias`` of its group, or the
        leave-one-out estimate; NaN in groups that are too small.
    """
    if method not in ("median", "huber"):
        raise ValueError(f"clock method must be 'median' or 'huber', got {method!r}")
    if isinstance(min_satellites, bool) or not isinstance(min_satellites, (int, np.integer)) or min_satellites < 1:
        raise ValueError(f"min_satellites must be a positive integer, got {min_satellites!r}")
    raw = np.asarray(raw, dtype=float)
    epoch = np.asarray(epoch, dtype=int)
    system = np.asarray(system, dtype=int)
    n_epochs = int(epoch.max()) + 1 if n_epochs is None else int(n_epochs)
    systems = np.unique(system)
    col = np.searchsorted(systems, system)
    bias = np.full((n_epochs, systems.size), np.nan)
    per_row = np.full(raw.shape, np.nan)
    locate = np.median if method == "median" else _huber_location
    count = np.zeros((n_epochs, systems.size), dtype=int)
    np.add.at(count, (epoch, col), 1)
    order = np.lexsort((col, epoch))
    key = epoch[order] * systems.size + col[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    ends = np.r_[starts[1:], key.size]
    for a, b in zip(starts, ends):
        if b - a < min_satellites:
            continue
        rows = order[a:b]
        v = raw[rows]
        e, c = divmod(int(key[a]), systems.size)
        bias[e, c] = float(locate(v))
        if leave_one_out:
            for i, r in enumerate(rows):
                per_row[r] = float(locate(np.delete(v, i)))
        else:
            per_row[rows] = bias[e, c]
    return bias, systems, count, per_row


@dataclass(frozen=True)
class SmartlocResiduals:
    """Pseudorange residuals against the ground truth, per row and per satellite channel.

    Attributes
    ----------
    epoch_times : ndarray (n_epochs,)
        [s].
    channel_names : list of str (n_channels,)
        ``"G12"``, ``"R301"``, ..., sorted by system then satellite id.
    channel_system, channel_id : ndarray of int (n_channels,)
    epoch, channel : ndarray of int (n,)
        Epoch and channel index of each pseudorange row (epoch -1 outside
        the truth's span).
    range : ndarray (n,)
        Geometric range from the ground truth [m].
    raw : ndarray (n,)
        Pseudorange minus range [m] (receiver clock still in it).
    clock : ndarray (n,)
        Clock (+ inter-system bias) removed from each row [m] (the group's
        estimate, or the leave-one-out one); NaN where the group had too few
        satellites.
    residual : ndarray (n,)
        ``raw - clock`` [m]; NaN where not valid.
    valid : ndarray of bool (n,)
        Row inside the truth's span and in a group with a clock.
    clock_bias : ndarray (n_epochs, s)
        Per epoch and system, from all satellites of the group [m] (columns: ``systems``).
    systems : ndarray of int (s,)
    elevation, cn0, variance : ndarray (n,)
        Copied from the pseudoranges ([rad], [dB-Hz], [m^2]).
    counts : dict
        ``rows``, ``outside_truth``, ``small_group`` (rows left out), ``valid``.
    settings : dict
        ``earth_rotation``, ``clock``, ``min_satellites``, ``leave_one_out``.
    """

    epoch_times: np.ndarray
    channel_names: list
    channel_system: np.ndarray
    channel_id: np.ndarray
    epoch: np.ndarray
    channel: np.ndarray
    range: np.ndarray
    raw: np.ndarray
    clock: np.ndarray
    residual: np.ndarray
    valid: np.ndarray
    clock_bias: np.ndarray
    systems: np.ndarray
    elevation: np.ndarray
    cn0: np.ndarray
    variance: np.ndarray
    counts: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)

    @property
    def n_epochs(self) -> int:
        return int(self.epoch_times.size)

    @property
    def n_channels(self) -> int:
        return len(self.channel_names)

    def channels(self, values=None) -> np.ndarray:
        """Per-row values laid out as (n_epochs, n_channels), NaN where absent or not valid.

        Parameters
        ----------
        values : ndarray (n,), optional
            Default :attr:`residual`.
        """
        v = self.residual if values is None else np.asarray(values, dtype=float)
        if v.shape != self.epoch.shape:
            raise ValueError(f"expected one value per row {self.epoch.shape}, got shape {v.shape}")
        out = np.full((self.n_epochs, self.n_channels), np.nan)
        ok = self.valid
        out[self.epoch[ok], self.channel[ok]] = v[ok]
        return out


def pseudorange_residuals(pr: SmartlocPseudoranges, truth: SmartlocTruth, *, earth_rotation: bool = True,
                          clock: str = "median", min_satellites: int = 3,
                          leave_one_out: bool = True) -> SmartlocResiduals:
    """Pseudorange residuals against the ground truth, receiver clock removed per epoch and system.

    See the module docstring for the model, the Earth-rotation evidence and
    the choice of the clock estimate.

    Parameters
    ----------
    pr : SmartlocPseudoranges
    truth : SmartlocTruth
    earth_rotation : bool, default True
        Correct the satellite positions for the Earth's rotation during the
        signal travel time (Sagnac).
    clock : {"median", "huber"}, default "median"
        Estimate of the common bias of each (epoch, system) group.
    min_satellites : int, default 3
        Groups with fewer satellites get no residual (NaN, counted).
    leave_one_out : bool, default True
        Remove from each satellite the clock estimated from the *other*
        satellites of its group, so that no residual is zero by construction.

    Returns
    -------
    SmartlocResiduals

    Raises
    ------
    ValueError
        Bad ``clock`` or ``min_satellites``, or no pseudorange inside the
        truth's time span.
    """
    inside = truth.covers(pr.time)
    if not inside.any():
        raise ValueError(f"no pseudorange time lies in the ground truth's span "
                         f"[{truth.time[0]:g}, {truth.time[-1]:g}] s")
    epoch_times = np.unique(pr.time[inside])
    epoch = np.where(inside, np.searchsorted(epoch_times, pr.time), -1)
    rng = np.full(len(pr), np.nan)
    rx = truth.position_at(pr.time[inside])
    rng[inside] = geometric_range(rx, pr.sat_ecef[inside], earth_rotation=earth_rotation)
    raw = pr.pseudorange - rng
    idx = np.flatnonzero(inside)
    bias, systems, _, clk_in = clock_per_epoch(raw[idx], epoch[idx], pr.system[idx], n_epochs=epoch_times.size,
                                               method=clock, min_satellites=min_satellites,
                                               leave_one_out=leave_one_out)
    clk = np.full(len(pr), np.nan)
    clk[idx] = clk_in
    valid = inside & np.isfinite(clk)
    residual = np.where(valid, raw - clk, np.nan)
    # channels: one per (system, satellite), sorted
    key = pr.system.astype(np.int64) * 100_000 + pr.sat_id
    ukeys, channel = np.unique(key, return_inverse=True)
    ch_sys, ch_id = ukeys // 100_000, ukeys % 100_000
    names = [f"{SYSTEMS[int(s)]}{int(i):02d}" for s, i in zip(ch_sys, ch_id)]
    counts = {"rows": len(pr), "outside_truth": int((~inside).sum()),
              "small_group": int((inside & ~np.isfinite(clk)).sum()), "valid": int(valid.sum())}
    return SmartlocResiduals(
        epoch_times=epoch_times, channel_names=names, channel_system=ch_sys.astype(int),
        channel_id=ch_id.astype(int), epoch=epoch, channel=channel.astype(int), range=rng, raw=raw, clock=clk,
        residual=residual, valid=valid, clock_bias=bias, systems=systems, elevation=pr.elevation, cn0=pr.cn0,
        variance=pr.variance, counts=counts,
        settings={"earth_rotation": bool(earth_rotation), "clock": clock, "min_satellites": int(min_satellites),
                  "leave_one_out": bool(leave_one_out)})


@register_reader("raw-gnss", "smartloc")
def _read_pseudoranges(path: Path, options: ReadOptions) -> RawPseudoranges:
    """The registered reader: the ``pseudorange3`` rows as corrected RawPseudoranges (no
    options: every system is read; a pipeline keeps those it uses)."""
    return to_raw_pseudoranges(read_pseudoranges(path))


@register_reader("odometry", "smartloc")
def _read_odometry(path: Path, options: ReadOptions) -> WheelOdometry:
    """The registered reader: the ``odom3`` rows (no options)."""
    return read_odometry(path)


@register_reader("reference", "smartloc")
def _read_reference(path: Path, options: ReadOptions) -> Trajectory:
    """The registered reader: the ground truth's positions (no velocity or attitude)."""
    from ..geodesy.frames import ecef_to_lla
    gt = read_ground_truth(path)
    return Trajectory(time=gt.time, lla=ecef_to_lla(gt.pos_ecef), v_n=None, q_nb=None)
