"""GPS pseudoranges from a RINEX observation file (2.x or 3.x), read with georinex.

Any receiver whose data RTKLIB's ``convbin`` (or the maker's tool) converts to RINEX
can then be processed by single-point positioning like a phone log
(:mod:`mixnav.experiment.spp_process`, ``raw_gnss.format = "rinex-obs"``).

The L1 C/A pseudorange is taken: ``C1C`` (RINEX 3) or ``C1`` (RINEX 2). Epoch times are
those the file gives (GPS time for GPS observations) and become GPS week and seconds
of week. Satellites other than GPS are left out (counted in ``rejected``), as are
missing values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError

#: GPS time origin (1980-01-06 00:00:00) as numpy datetime64
_GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
_WEEK = 604800.0


@dataclass(frozen=True, eq=False)
class RinexPseudoranges:
    """GPS L1 C/A pseudoranges of a RINEX observation file, grouped by epoch (the fields
    :func:`mixnav.gnss.spp.solve_epochs` reads, as :class:`mixnav.io.android.AndroidPseudoranges`).

    Attributes
    ----------
    week : ndarray of int (k,); tow : ndarray (k,) [s]
        Epoch times (GPS week, seconds of week).
    epoch : ndarray of int (m,); prn : ndarray of int (m,); pseudorange : ndarray (m,) [m]
    code : str
        The observation code read (``C1C`` or ``C1``).
    rejected : dict
        Observations left out, per reason.
    source : str
    """

    week: np.ndarray
    tow: np.ndarray
    epoch: np.ndarray
    prn: np.ndarray
    pseudorange: np.ndarray
    code: str
    rejected: dict = field(default_factory=dict)
    source: str = ""

    def __len__(self) -> int:
        return len(self.tow)


def read_rinex_obs(path) -> RinexPseudoranges:
    """Read the GPS L1 C/A pseudoranges of a RINEX 2.x/3.x observation file.

    Raises
    ------
    DataError
        A file georinex cannot read, one without ``C1C``/``C1`` observations or without
        any GPS pseudorange, or epoch times that do not increase (naming the file).
    """
    import georinex as gr
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", file=str(path))
    import warnings
    try:
        with warnings.catch_warnings():   # georinex's per-epoch xarray concat warns of a future default
            warnings.simplefilter("ignore", FutureWarning)
            ds = gr.load(path)
    except Exception as exc:     # georinex raises many kinds for a damaged file
        raise DataError(f"not a readable RINEX observation file ({type(exc).__name__}: {exc})",
                        file=str(path)) from None
    code = next((c for c in ("C1C", "C1") if c in getattr(ds, "data_vars", {})), None)
    if code is None:
        raise DataError("no L1 C/A pseudorange (C1C or C1) in the file", file=str(path))
    svs = [str(s) for s in ds.sv.values]
    values = np.asarray(ds[code].values, dtype=float)          # (time, sv)
    times = np.asarray(ds.time.values).astype("datetime64[ns]")
    if len(times) > 1 and np.any(np.diff(times) <= np.timedelta64(0, "ns")):
        raise DataError("epoch times do not increase", file=str(path))
    gps = np.array([s.startswith("G") for s in svs])
    rejected = {}
    other = int(np.isfinite(values[:, ~gps]).sum())
    if other:
        rejected["not GPS"] = other
    values = values[:, gps]
    bad = [s for s, g in zip(svs, gps) if g and not (len(s) == 3 and s[1:].isdigit() and 1 <= int(s[1:]) <= 32)]
    if bad:
        raise DataError(f"satellite name {bad[0]!r} is not a GPS PRN (G01-G32)", file=str(path))
    prns = np.array([int(s[1:]) for s, g in zip(svs, gps) if g], dtype=np.int64)
    ok = np.isfinite(values) & (values > 0)
    if not ok.any():
        raise DataError(f"no GPS {code} pseudorange in the file", file=str(path))
    since = (times - _GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64) / 1e9
    week = np.floor(since / _WEEK).astype(np.int64)
    tow = since - week * _WEEK
    keep = ok.any(axis=1)                       # epochs with at least one GPS pseudorange
    idx = np.cumsum(keep) - 1
    t_i, s_i = np.nonzero(ok)
    return RinexPseudoranges(week=week[keep], tow=tow[keep], epoch=idx[t_i].astype(np.int64), prn=prns[s_i],
                             pseudorange=values[t_i, s_i], code=code, rejected=rejected, source=str(path))
