"""Reader of RTKLIB ``.pos`` solution files (as GNSS input or as reference).

Supported: time as ``yyyy/mm/dd hh:mm:ss.sss`` or ``week tow`` (GPST), and
position as latitude/longitude in degrees with ellipsoidal height, or ECEF x,
y, z; the quality flag, satellite count, the standard deviations, and the
velocity columns of RTKLIB demo5 when present. Times are returned as GPS
seconds counted from the Unix epoch (no leap seconds), the scale RTKLIB time
tags use. Latitude/longitude in d'" form is refused with a clear message.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..data import GnssFixes, Trajectory
from ..errors import DataError
from ..geodesy.frames import dcm_ecef_to_ned, ecef_to_lla
from .registry import ReadOptions, register_reader
from .tables import check_fix_values, check_times, read_numeric

GPS_EPOCH_UNIX = 315964800.0  # 1980-01-06 00:00:00 in Unix seconds
_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)

#: Quality flags of RTKLIB.
QUALITY = {1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp"}


@dataclass(frozen=True)
class PosSolution:
    """The columns of a ``.pos`` file in SI units.

    Attributes
    ----------
    time : ndarray (n,)
        GPS seconds since 1970-01-01.
    lla : ndarray (n, 3)
        rad, rad, m.
    quality, n_sat : ndarray of int (n,)
    sd_ned : ndarray (n, 3)
        1-sigma north, east, down [m].
    vel_ned, sd_vel : ndarray (n, 3) or None
        Velocity north, east, down [m/s] and its 1-sigma.
    """

    time: np.ndarray
    lla: np.ndarray
    quality: np.ndarray
    n_sat: np.ndarray
    sd_ned: np.ndarray
    vel_ned: np.ndarray | None
    sd_vel: np.ndarray | None
    source: str

    def select(self, qualities=(1,)) -> np.ndarray:
        """Mask of the epochs whose quality flag is in ``qualities``."""
        return np.isin(self.quality, list(qualities))

    def fixes(self, qualities=(1, 2, 5), min_sigma: float = 0.0, velocity_delay: float = 0.0) -> GnssFixes:
        """GNSS fixes of the chosen qualities; sigmas floored at ``min_sigma`` [m].

        ``velocity_delay`` [s]: the velocity columns are valid at ``t - velocity_delay``
        (:func:`velocity_at_epochs`); they are moved to the epoch times, interpolated
        between the chosen epochs only. A pipeline that withholds fixes reads them with
        no delay and moves the velocities of the fixes it keeps
        (:mod:`mixnav.experiment.pipelines.ins_fixes`).
        """
        m = self.select(qualities)
        if not m.any():
            raise DataError(f"no epoch with quality in {list(qualities)}", file=self.source)
        sd = np.maximum(self.sd_ned[m], max(min_sigma, 1e-4))
        if self.vel_ned is None:
            return GnssFixes(time=self.time[m], lla=self.lla[m], pos_sigma=sd, source=self.source)
        vel = velocity_at_epochs(self.time[m], self.vel_ned[m], velocity_delay)
        sv = np.maximum(self.sd_vel[m], 1e-4)
        return GnssFixes(time=self.time[m], lla=self.lla[m], pos_sigma=sd, vel_n=vel,
                         vel_sigma=sv, source=self.source)

    def velocity_at_epochs(self, delay: float) -> np.ndarray:
        """The velocity at the epoch times when the file's velocity is valid ``delay`` [s]
        earlier, over every epoch of the file (:func:`velocity_at_epochs`)."""
        return velocity_at_epochs(self.time, self.vel_ned, delay)

    def reference(self, qualities=(1,)) -> Trajectory:
        """Reference trajectory (position, and velocity when present) of the chosen qualities."""
        m = self.select(qualities)
        if not m.any():
            raise DataError(f"no epoch with quality in {list(qualities)} for the reference", file=self.source)
        return Trajectory(time=self.time[m], lla=self.lla[m],
                          v_n=None if self.vel_ned is None else self.vel_ned[m], q_nb=None)


def velocity_at_epochs(time: np.ndarray, vel: np.ndarray | None, delay: float) -> np.ndarray | None:
    """The velocity at the epoch times when each reported velocity is valid ``delay`` [s] earlier.

    RTKLIB's velocity can be an average over the interval before the epoch
    (a backward difference of positions, or a Doppler over the interval):
    then it is the velocity at ``t - dt/2``, not at ``t``
    (drive-0708: 0.125 s at 4 Hz, see
    ``benchmarks/results/drive0708_installation.md``). Each epoch's velocity
    is interpolated linearly between the two reported velocities whose
    validity times ``t_j - delay`` bracket it. Where they do not (the last
    ``delay`` of the record, or a gap longer than 1.5 times the median
    interval) the reported value is kept. Only the epochs given take part: pass
    the fixes a filter uses (after quality selection and withholding), so that a
    fix next to a withheld window carries nothing of the withheld ones.

    Parameters
    ----------
    time : ndarray (n,)
        Epoch times [s], increasing.
    vel : ndarray (n, 3) or None
        Reported velocities [m/s]; None gives None.
    delay : float
        How much earlier than its epoch each velocity is valid [s].
    """
    v, t = vel, np.asarray(time, dtype=float)
    if v is None or delay == 0.0 or len(t) < 2:
        return v
    tv = t - delay                       # when each reported velocity is valid
    j = np.searchsorted(tv, t, side="right")  # tv[j-1] <= t < tv[j]
    ok = (j >= 1) & (j < len(t))
    jj = np.clip(j, 1, len(t) - 1)
    span = tv[jj] - tv[jj - 1]
    ok &= span <= 1.5 * float(np.median(np.diff(t)))
    w = np.where(ok, (t - tv[jj - 1]) / np.where(span > 0, span, 1.0), 0.0)[:, None]
    out = np.array(v, dtype=float, copy=True)
    out[ok] = ((1.0 - w) * v[jj - 1] + w * v[jj])[ok]
    return out


def _header(path: Path) -> tuple[list[str], int]:
    names, n = None, 0
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if not line.startswith("%"):
                break
            n += 1
            cols = line[1:].split()
            # the column header starts with the time system and names the position columns
            if cols and cols[0] in ("GPST", "UTC") and any(c.startswith(("latitude", "x-ecef")) for c in cols):
                names = cols
    if names is None:
        raise DataError("no RTKLIB column header ('%  GPST ...' line) found", file=str(path), line=n or 1)
    return names, n


def _ecef_sigmas_to_ned(sd6: np.ndarray, lla: np.ndarray) -> np.ndarray:
    """NED 1-sigma from RTKLIB's ECEF ``sdx sdy sdz sdxy sdyz sdzx``.

    RTKLIB writes the off-diagonal terms as signed square roots of the
    covariances; the full ECEF covariance is rotated into NED.
    """
    sx, sy, sz, sxy, syz, szx = sd6.T
    cov = np.empty((len(sd6), 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = sx ** 2, sy ** 2, sz ** 2
    cov[:, 0, 1] = cov[:, 1, 0] = np.sign(sxy) * sxy ** 2
    cov[:, 1, 2] = cov[:, 2, 1] = np.sign(syz) * syz ** 2
    cov[:, 2, 0] = cov[:, 0, 2] = np.sign(szx) * szx ** 2
    c = dcm_ecef_to_ned(lla[:, 0], lla[:, 1])
    ned = c @ cov @ np.swapaxes(c, 1, 2)
    return np.sqrt(np.abs(np.diagonal(ned, axis1=1, axis2=2)))


def read_pos(path, max_gap: float | None = None, gap_action: str = "warn") -> PosSolution:
    """Read an RTKLIB ``.pos`` file.

    Raises
    ------
    DataError
        Missing header, unsupported layout, malformed line, time going
        backwards or repeating, each naming the file and line.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("RTKLIB solution file does not exist", file=str(path))
    names, n_head = _header(path)
    if names[0] == "UTC":
        raise DataError("UTC time stamps are not supported; output GPST from RTKLIB", file=str(path), line=n_head)
    with open(path, encoding="utf-8", errors="replace") as fh:
        first = next((ln for ln in fh if ln.strip() and not ln.startswith("%")), None)
    if first is None:
        raise DataError("RTKLIB solution file is empty (no data lines)", file=str(path))
    calendar = "/" in first.split()[0]
    low = [c.lower() for c in names]
    if any(c.startswith("latitude(d'") for c in low):
        raise DataError("latitude/longitude in d'\" form are not supported; output degrees", file=str(path),
                        line=n_head)
    ecef = any(c.startswith("x-ecef") for c in low)
    has_vel = any(c.startswith("vn(") for c in low)
    n_fields = 14 + (9 if has_vel else 0)  # time (2 tokens) + 3 pos + Q + ns + 6 sd + age + ratio [+ 9]

    def conv(toks):
        if len(toks) != n_fields + 1:
            raise ValueError(f"expected {n_fields + 1} fields, found {len(toks)}")
        if calendar:
            dt = datetime.strptime(toks[0] + " " + toks[1], "%Y/%m/%d %H:%M:%S.%f").replace(tzinfo=timezone.utc)
            t = (dt - _EPOCH).total_seconds()
        else:
            t = GPS_EPOCH_UNIX + float(toks[0]) * 604800.0 + float(toks[1])
        return [t] + [float(x) for x in toks[2:]]

    tab = read_numeric(path, n_fields, comment="%", converters=conv, what="RTKLIB solution")
    v = tab.values
    check_times(v[:, 0], tab.lines, str(path), max_gap=max_gap, gap_action=gap_action, what="solution")
    if ecef:
        lla = ecef_to_lla(v[:, 1:4])
        sd = _ecef_sigmas_to_ned(v[:, 6:12], lla)
    else:
        lla = np.column_stack([np.radians(v[:, 1]), np.radians(v[:, 2]), v[:, 3]])
        sd = np.abs(v[:, 6:9])  # sdn, sde, sdu (down has the sigma of up)
    vel = sdv = None
    if has_vel:
        vel = np.column_stack([v[:, 14], v[:, 15], -v[:, 16]])
        sdv = np.abs(v[:, 17:20])
    check_fix_values(lla, sd, tab.lines, str(path), vel)
    return PosSolution(time=v[:, 0], lla=lla, quality=v[:, 4].astype(int), n_sat=v[:, 5].astype(int),
                       sd_ned=sd, vel_ned=vel, sd_vel=sdv, source=str(path))


@register_reader("gnss-fixes", "rtklib-pos")
def _read_fixes(path: Path, options: ReadOptions) -> GnssFixes:
    """The registered GNSS reader (``options``: ``qualities``, ``min_sigma``, ``velocity_delay``)."""
    return read_pos(path).fixes(qualities=options.get("qualities", (1, 2, 5)), min_sigma=options.get("min_sigma", 0.0),
                                velocity_delay=options.get("velocity_delay", 0.0))


@register_reader("reference", "rtklib-pos")
def _read_reference(path: Path, options: ReadOptions) -> Trajectory:
    """The registered reference reader (``options``: ``qualities``; ``velocity_delay``: the velocity
    at the epochs, as the filter's GNSS velocity is)."""
    from dataclasses import replace
    qualities, delay = options.get("qualities", (1,)), options.get("velocity_delay", 0.0)
    pos = read_pos(path)
    ref = pos.reference(qualities=qualities)
    if delay and ref.v_n is not None:
        ref = replace(ref, v_n=pos.velocity_at_epochs(delay)[pos.select(qualities)])
    return ref
