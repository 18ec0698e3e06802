"""GPS broadcast ephemeris: satellite position, velocity and clock from a RINEX navigation file.

Reading
-------
The RINEX navigation file (version 2 or 3, GPS records only) is parsed by
`georinex <https://github.com/geospace-code/georinex>`_, a maintained reader
that depends on xarray only (plus small compression helpers). It was chosen
over gnss-lib-py, whose released version pins pandas < 3 and xarray 2024 and
would downgrade this environment; georinex 1.16 works with the numpy 2 /
pandas 3 / xarray stack here. georinex's own orbit routine
(``georinex.keplerian.keplerian2ecef``) is not used: it solves Kepler's
equation with a single fixed-point step (an error up to about e^2 A, a
kilometre at e = 0.01), uses a GM other than the GPS value, and fails with
the xarray installed here. The orbit and clock are written
from IS-GPS-200 directly, in :func:`mixnav.gnss.orbits.kepler_states` (the
Keplerian kernel every system shares, called here with the GPS constants).
Other systems: :mod:`mixnav.gnss.multi_ephemeris`.

Everything georinex may raise (unreadable text, wrong file type) is turned
into a :class:`~mixnav.errors.DataError` naming the file; records georinex
leaves partly empty (a truncated file) are refused by name (PRN and epoch).

Computation (IS-GPS-200, section 20.3.3.4.3, Table 20-IV)
---------------------------------------------------------
Position: mean motion, Kepler's equation solved by Newton iterations to
machine precision, true anomaly, second-harmonic corrections of argument of
latitude, radius and inclination, longitude of the ascending node in ECEF.
Velocity: the analytic time derivative of those same expressions (no finite
differences), in the rotating ECEF frame.
Clock (section 20.3.3.3.3.1): ``dt_sv = af0 + af1 (t - toc) + af2 (t - toc)^2
+ dt_r`` with the relativistic term ``dt_r = F e sqrt(A) sin(E_k)``,
``F = -4.442807633e-10 s/m^1/2``. The group delay (section 20.3.3.3.3.2) is
applied for the single-frequency L1 C/A user, ``dt_sv(L1) = dt_sv - T_GD``,
unless ``apply_tgd=False``. The drift is the time derivative of the
polynomial plus relativistic term.

Which record
------------
For each satellite, among its healthy records (SV health word 0), the one
whose ``toe`` is nearest to the requested time; it is used when
``|t - toe| <= max_age`` (default 2 h 15 min: the 4 h curve fit interval
centred on ``toe``, plus the 15 min by which uploads may precede ``toe``).
Satellites with no record, only stale records or only unhealthy records are
skipped and reported in an :class:`EphemerisSkips` (never an exception).

Time is GPS time as ``(week, tow)``; ``week`` is the continuous GPS week
(RINEX 2 and 3 navigation files give it without the 1024 roll-over).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError
from .geometry import SECONDS_PER_WEEK, SatelliteStates
from .orbits import GPS as GPS_CONSTANTS
from .orbits import kepler_states

#: Relativistic clock constant F = -2 sqrt(GM) / c^2 [s/m^(1/2)] (IS-GPS-200, 20.3.3.3.3.1).
F_REL = GPS_CONSTANTS.f_rel
#: Default validity window around toe [s].
DEFAULT_MAX_AGE = 2 * 3600.0 + 15 * 60.0

# georinex variable name -> our field name
_FIELDS = {
    "SVclockBias": "af0", "SVclockDrift": "af1", "SVclockDriftRate": "af2",
    "Crs": "crs", "DeltaN": "delta_n", "M0": "m0", "Cuc": "cuc", "Eccentricity": "e",
    "Cus": "cus", "sqrtA": "sqrt_a", "Toe": "toe", "Cic": "cic", "Omega0": "omega0",
    "Cis": "cis", "Io": "i0", "Crc": "crc", "omega": "omega", "OmegaDot": "omega_dot",
    "IDOT": "idot", "GPSWeek": "week", "health": "health", "TGD": "tgd",
}
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")


@dataclass(frozen=True)
class EphemerisSkips:
    """Satellites asked for but not returned, and why.

    Attributes
    ----------
    prn : ndarray of int (k,)
    reason : tuple of str (k,)
        ``"no ephemeris"``, ``"stale ephemeris"`` (nearest toe farther than
        ``max_age``) or ``"unhealthy"``.
    """

    prn: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    reason: tuple = ()

    def __len__(self) -> int:
        return len(self.prn)

    def counts(self) -> dict[str, int]:
        """Number of skipped satellites per reason."""
        out: dict[str, int] = {}
        for r in self.reason:
            out[r] = out.get(r, 0) + 1
        return out


class BroadcastEphemeris:
    """GPS broadcast ephemeris records, stacked as arrays (one entry per record).

    Build it with :meth:`from_rinex`; query it with :meth:`states`.

    Parameters
    ----------
    records : dict of str -> ndarray (m,)
        One array per Keplerian / clock parameter (names as in
        ``_FIELDS``), plus ``prn`` and ``toc_week``, ``toc`` (the clock
        reference time as week and seconds of week). Angles in rad, angular
        rates in rad/s, lengths in m, ``sqrt_a`` in m^(1/2), times in s.
    source : str
        Where the records came from (for messages).
    iono_alpha, iono_beta : ndarray (4,) or None
        Klobuchar coefficients of the file header (s, s/semicircle, ...), as
        broadcast.
    max_age : float
        Validity window ``|t - toe|`` [s].
    """

    def __init__(self, records: dict, source: str = "", iono_alpha=None, iono_beta=None,
                 max_age: float = DEFAULT_MAX_AGE):
        self.rec = {k: np.asarray(v) for k, v in records.items()}
        self.source = source
        self.iono_alpha = None if iono_alpha is None else np.asarray(iono_alpha, float)
        self.iono_beta = None if iono_beta is None else np.asarray(iono_beta, float)
        self.max_age = float(max_age)

    def __len__(self) -> int:
        return len(self.rec["prn"])

    @property
    def prns(self) -> np.ndarray:
        """Satellites with at least one record, sorted."""
        return np.unique(self.rec["prn"])

    # ------------------------------------------------------------------ reading
    @classmethod
    def from_rinex(cls, path, max_age: float = DEFAULT_MAX_AGE) -> "BroadcastEphemeris":
        """Read the GPS records of a RINEX 2/3 navigation file.

        Raises
        ------
        DataError
            Missing file, not a navigation file, no GPS record, or a record
            with missing parameters (a truncated file); the message names
            the file.
        """
        path = Path(path)
        if not path.is_file():
            raise DataError("RINEX navigation file not found", file=str(path))
        try:
            import georinex
        except ImportError as exc:  # pragma: no cover - georinex is a dependency
            raise DataError(f"reading RINEX needs georinex ({exc})", file=str(path)) from exc
        try:
            with open(path, "rb") as fh:
                head = fh.read(80).decode("ascii", "replace")
        except OSError as exc:
            raise DataError(f"cannot read: {exc}", file=str(path)) from exc
        if "RINEX VERSION / TYPE" not in head:
            raise DataError("not a RINEX file: the first line is not a 'RINEX VERSION / TYPE' header "
                            f"(it reads {head.splitlines()[0][:60]!r})" if head else "empty file",
                            file=str(path), line=1)
        if head[20:21].upper() != "N":
            raise DataError(f"not a GPS navigation file: RINEX file type {head[20:40].strip()!r} "
                            "(expected 'N', navigation data)", file=str(path), line=1)
        try:
            import warnings
            with warnings.catch_warnings():   # georinex's per-record xarray merge warns of future defaults
                warnings.simplefilter("ignore", FutureWarning)
                nav = georinex.load(path, use="G")
        except Exception as exc:  # georinex raises many types; report them at our boundary
            raise DataError(f"cannot parse as RINEX navigation ({type(exc).__name__}: {exc})",
                            file=str(path)) from exc
        if nav is None or getattr(nav, "attrs", {}).get("rinextype") != "nav":
            raise DataError("not a RINEX navigation file", file=str(path))
        missing = [k for k in _FIELDS if k not in nav]
        if missing:
            raise DataError(f"no GPS ephemeris records (fields {missing[:3]}... absent)", file=str(path))
        records = _stack(nav, str(path))
        iono = nav.attrs.get("ionospheric_corr_GPS")
        alpha = beta = None
        if iono is not None and np.size(iono) == 8 and np.all(np.isfinite(iono)):
            alpha, beta = np.asarray(iono[:4], float), np.asarray(iono[4:], float)
        return cls(records, source=str(path), iono_alpha=alpha, iono_beta=beta, max_age=max_age)

    # ------------------------------------------------------------------ selection
    def _select(self, week, tow, prns):
        """Record index per asked satellite (-1 if none) and the skip reasons."""
        t = self._system_time(np.asarray(week, float) * SECONDS_PER_WEEK + np.asarray(tow, float))
        t = np.broadcast_to(t, prns.shape)
        t_oe = self.rec["week"] * SECONDS_PER_WEEK + self.rec["toe"]  # (m,)
        age = np.abs(t[:, None] - t_oe[None, :])                       # (n, m)
        same = prns[:, None] == self.rec["prn"][None, :]
        healthy = (self.rec["health"] == 0)[None, :]
        cand = np.where(same & healthy, age, np.inf)
        idx = np.argmin(cand, axis=1) if cand.shape[1] else np.zeros(len(prns), int)
        best = cand[np.arange(len(prns)), idx] if cand.shape[1] else np.full(len(prns), np.inf)
        ok = best <= self.max_age
        reasons = []
        for k in np.flatnonzero(~ok):
            if not same[k].any():
                reasons.append("no ephemeris")
            elif not (same[k] & healthy[0]).any():
                reasons.append("unhealthy")
            else:
                reasons.append("stale ephemeris")
        return np.where(ok, idx, -1), t, EphemerisSkips(prns[~ok].astype(int), tuple(reasons))

    def states(self, t_gps_week, t_gps_tow, prns=None, apply_tgd: bool = True) -> SatelliteStates:
        """Satellite states at GPS time(s); satellites without usable ephemeris are left out.

        See :meth:`states_and_skips` for the parameters and the list of
        satellites left out.
        """
        return self.states_and_skips(t_gps_week, t_gps_tow, prns, apply_tgd)[0]

    def states_and_skips(self, t_gps_week, t_gps_tow, prns=None,
                         apply_tgd: bool = True) -> tuple[SatelliteStates, EphemerisSkips]:
        """Satellite position, velocity and clock at GPS time(s).

        Parameters
        ----------
        t_gps_week : int or ndarray of int (n,)
            GPS week (continuous).
        t_gps_tow : float or ndarray (n,)
            Seconds of week [s]; one per satellite (e.g. each satellite's
            transmit time) or one for all.
        prns : array_like of int (n,) or None
            Satellites asked for; None: every satellite in the file.
        apply_tgd : bool
            Subtract T_GD from the clock (L1 C/A single-frequency user).

        Returns
        -------
        states : SatelliteStates
            For the satellites with a usable record, in the order asked.
            ``clock_bias`` [s] includes the relativistic term.
        skips : EphemerisSkips
            The satellites left out and why.
        """
        prns = self.prns if prns is None else np.atleast_1d(np.asarray(prns, dtype=int))
        idx, t, skips = self._select(t_gps_week, t_gps_tow, prns)
        use = idx >= 0
        pos, vel, clk, drift = self._compute(idx[use], t[use], apply_tgd)
        return SatelliteStates(prns[use].astype(int), pos, vel, clk, drift), skips

    # ------------------------------------------------------------------ IS-GPS-200
    def _system_time(self, t_gps):
        """Continuous seconds in the records' time scale of continuous GPS seconds (GPS: the same)."""
        return t_gps

    def _compute(self, idx, t, apply_tgd):
        r = {k: v[idx] for k, v in self.rec.items()}
        return kepler_states(r, t, GPS_CONSTANTS, apply_group_delay=apply_tgd)


def _stack(nav, source: str) -> dict:
    """Flatten georinex's (time, sv) grid into one entry per record present."""
    prn_all = np.array([int(s[1:]) for s in nav["sv"].values])
    arrays = {k: np.asarray(nav[name].values, float) for name, k in _FIELDS.items()}
    present = np.zeros(arrays["m0"].shape, bool)
    for a in arrays.values():
        present |= np.isfinite(a)
    complete = np.ones_like(present)
    for a in arrays.values():
        complete &= np.isfinite(a)
    bad = present & ~complete
    if bad.any():
        it, isv = np.argwhere(bad)[0]
        when = str(nav["time"].values[it])[:19]
        raise DataError(f"incomplete ephemeris record for G{prn_all[isv]:02d} at {when} "
                        f"({int(bad.sum())} such records; is the file truncated?)", file=source)
    it, isv = np.nonzero(complete)
    if it.size == 0:
        raise DataError("no complete GPS ephemeris record", file=source)
    rec = {k: a[it, isv] for k, a in arrays.items()}
    rec["prn"] = prn_all[isv]
    toc_s = (nav["time"].values.astype("datetime64[ns]")[it] - _GPS_EPOCH) / np.timedelta64(1, "s")
    rec["toc_week"] = np.floor(toc_s / SECONDS_PER_WEEK)
    rec["toc"] = toc_s - rec["toc_week"] * SECONDS_PER_WEEK
    return rec
