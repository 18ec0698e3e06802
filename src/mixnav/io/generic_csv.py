"""The generic CSV layout: bring any data by converting it to this.

Comma-separated, one header line naming the columns with their units in
brackets, in any order; every value in SI or any unit :mod:`mixnav.units`
reads. See docs/data_formats.md.

IMU (rates or increments, body frame forward-right-down)::

    time[s], wx[deg/s], wy[deg/s], wz[deg/s], fx[m/s^2], fy[m/s^2], fz[m/s^2]
    time[s], dthx[rad], dthy[rad], dthz[rad], dvx[m/s], dvy[m/s], dvz[m/s]

GNSS fixes (velocity columns optional, all six together)::

    time[s], lat[deg], lon[deg], height[m], sd_n[m], sd_e[m], sd_d[m],
    vn[m/s], ve[m/s], vd[m/s], sd_vn[m/s], sd_ve[m/s], sd_vd[m/s]

Reference (velocity and attitude optional, each group of three together)::

    time[s], lat[deg], lon[deg], height[m], vn[m/s], ve[m/s], vd[m/s],
    roll[deg], pitch[deg], yaw[deg]
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import units as u
from ..attitude import euler_to_quat
from ..data import GnssFixes, ImuData, Trajectory
from ..errors import DataError
from .imu_checks import check_plausible, rates_to_increments
from .registry import ReadOptions, register_reader
from .tables import check_fix_values, check_times, header_fields, read_numeric

_COL = re.compile(r"^\s*([A-Za-z_]+)\s*\[(.*)\]\s*$")

_DIMS = {
    "time": u.TIME, "wx": u.ANGULAR_RATE, "wy": u.ANGULAR_RATE, "wz": u.ANGULAR_RATE,
    "fx": u.ACCELERATION, "fy": u.ACCELERATION, "fz": u.ACCELERATION,
    "dthx": u.ANGLE, "dthy": u.ANGLE, "dthz": u.ANGLE, "dvx": u.VELOCITY, "dvy": u.VELOCITY, "dvz": u.VELOCITY,
    "lat": u.ANGLE, "lon": u.ANGLE, "height": u.LENGTH, "sd_n": u.LENGTH, "sd_e": u.LENGTH, "sd_d": u.LENGTH,
    "vn": u.VELOCITY, "ve": u.VELOCITY, "vd": u.VELOCITY,
    "sd_vn": u.VELOCITY, "sd_ve": u.VELOCITY, "sd_vd": u.VELOCITY,
    "roll": u.ANGLE, "pitch": u.ANGLE, "yaw": u.ANGLE,
}
_IMU_RATE = ["time", "wx", "wy", "wz", "fx", "fy", "fz"]
_IMU_INC = ["time", "dthx", "dthy", "dthz", "dvx", "dvy", "dvz"]
_GNSS = ["time", "lat", "lon", "height", "sd_n", "sd_e", "sd_d"]
_GNSS_VEL = ["vn", "ve", "vd", "sd_vn", "sd_ve", "sd_vd"]
_REF = ["time", "lat", "lon", "height"]


def _header(path: Path, layouts: list[list[str]], what: str):
    names, factors = [], []
    for col in header_fields(path, what):
        m = _COL.match(col)
        if not m:
            raise DataError(f"header column {col.strip()!r} is not 'name[unit]'", file=str(path), line=1)
        name, unit = m.group(1), m.group(2)
        if name not in _DIMS:
            raise DataError(f"unknown column {name!r}; see docs/data_formats.md", file=str(path), line=1)
        try:
            factors.append(u.parse_quantity(f"1 {unit}", _DIMS[name]) if unit.strip() else
                           u.parse_quantity("1", _DIMS[name]))
        except u.UnitError as exc:
            raise DataError(f"column {name!r}: {exc}", file=str(path), line=1) from None
        names.append(name)
    if len(set(names)) != len(names):
        raise DataError("a column appears twice in the header", file=str(path), line=1)
    for lay in layouts:
        if set(names) == set(lay):
            break
    else:
        opts = " | ".join(", ".join(lay) for lay in layouts)
        raise DataError(f"columns {names} are not a known layout; expected one of: {opts}",
                        file=str(path), line=1)
    return names, np.array(factors)


def _values(path, names, factors, what):
    tab = read_numeric(path, len(names), delimiter=",", skip_lines=1, what=what)
    cols = {n: tab.values[:, i] * factors[i] for i, n in enumerate(names)}
    return tab, cols


def read_imu_csv(path, max_gap: float | None = None, gap_action: str = "warn", spike_action: str = "fail") -> ImuData:
    path = Path(path)
    names, fac = _header(path, [_IMU_RATE, _IMU_INC], "IMU")
    tab, c = _values(path, names, fac, "IMU")
    gaps = check_times(c["time"], tab.lines, str(path), max_gap=max_gap, gap_action=gap_action, what="IMU").gaps
    if "wx" in c:
        imu = rates_to_increments(c["time"], np.column_stack([c["wx"], c["wy"], c["wz"]]),
                                  np.column_stack([c["fx"], c["fy"], c["fz"]]), source=str(path))
        units = (names_unit(path, "wx"), names_unit(path, "fx"))
    else:
        t = c["time"]
        imu = ImuData(time=t[1:], dt=np.diff(t), dtheta=np.column_stack([c["dthx"], c["dthy"], c["dthz"]])[1:],
                      dvel=np.column_stack([c["dvx"], c["dvy"], c["dvz"]])[1:], source=str(path))
        units = (names_unit(path, "dthx"), names_unit(path, "dvx"))
    return replace(check_plausible(imu, *units, tab.lines[1:], spike_action), gaps=gaps)


def names_unit(path: Path, name: str) -> str:
    with open(path, encoding="utf-8", errors="replace") as fh:
        for col in fh.readline().split(","):
            m = _COL.match(col)
            if m and m.group(1) == name:
                return m.group(2)
    return "?"


def read_gnss_csv(path, max_gap: float | None = None, gap_action: str = "warn") -> GnssFixes:
    path = Path(path)
    names, fac = _header(path, [_GNSS, _GNSS + _GNSS_VEL], "GNSS")
    tab, c = _values(path, names, fac, "GNSS")
    check_times(c["time"], tab.lines, str(path), max_gap=max_gap, gap_action=gap_action, what="GNSS")
    sd = np.column_stack([c["sd_n"], c["sd_e"], c["sd_d"]])
    bad = np.nonzero(~(sd > 0).all(1))[0]
    if bad.size:
        raise DataError("standard deviations must be positive", file=str(path), line=int(tab.lines[bad[0]]))
    lla = np.column_stack([c["lat"], c["lon"], c["height"]])
    check_fix_values(lla, sd, tab.lines, str(path),
                     np.column_stack([c["vn"], c["ve"], c["vd"]]) if "vn" in c else None)
    if "vn" in c:
        return GnssFixes(time=c["time"], lla=lla, pos_sigma=sd, vel_n=np.column_stack([c["vn"], c["ve"], c["vd"]]),
                         vel_sigma=np.column_stack([c["sd_vn"], c["sd_ve"], c["sd_vd"]]), source=str(path))
    return GnssFixes(time=c["time"], lla=lla, pos_sigma=sd, source=str(path))


def read_reference_csv(path) -> Trajectory:
    path = Path(path)
    vel, att = ["vn", "ve", "vd"], ["roll", "pitch", "yaw"]
    names, fac = _header(path, [_REF, _REF + vel, _REF + att, _REF + vel + att], "reference")
    tab, c = _values(path, names, fac, "reference")
    check_times(c["time"], tab.lines, str(path), what="reference")
    return Trajectory(time=c["time"], lla=np.column_stack([c["lat"], c["lon"], c["height"]]),
                      v_n=np.column_stack([c[k] for k in vel]) if "vn" in c else None,
                      q_nb=euler_to_quat(np.column_stack([c[k] for k in att])) if "roll" in c else None)


@register_reader("imu", "csv")
def _read_imu(path: Path, options: ReadOptions) -> ImuData:
    """The registered IMU reader (``options``: ``max_gap``, ``gap_action``, ``spike_action``)."""
    return read_imu_csv(path, **options.imu_checks())


@register_reader("gnss-fixes", "csv")
def _read_gnss(path: Path, options: ReadOptions) -> GnssFixes:
    """The registered GNSS reader (no options: ``[gnss]``'s ``max_gap`` is checked on the fixes used)."""
    return read_gnss_csv(path)


@register_reader("reference", "csv")
def _read_reference(path: Path, options: ReadOptions) -> Trajectory:
    """The registered reference reader (no options)."""
    return read_reference_csv(path)
