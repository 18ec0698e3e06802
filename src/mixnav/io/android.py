"""Reader of Android GnssLogger text logs: GPS L1 C/A pseudoranges per epoch.

The format
----------
Comment lines start with ``#``; the line ``# Raw,<name>,<name>,...`` names the
columns of the ``Raw,`` rows (Android ``GnssClock`` + ``GnssMeasurement``
fields). Other row kinds (``Fix``, ``Nav``, ``Status``, ...) are ignored.

From raw fields to a pseudorange
--------------------------------
The convention of Google's gps-measurement-tools (the logger's own
documentation), re-derived here in integer nanoseconds because
``FullBiasNanos`` (~1e18) does not fit a float exactly:

- GPS week: ``floor(-FullBiasNanos / ns_per_week)``.
- Receive time, GPS nanoseconds of week::

      t_rx = TimeNanos + TimeOffsetNanos - (FullBiasNanos_0 + BiasNanos_0) - week * ns_per_week

  where ``FullBiasNanos_0, BiasNanos_0`` are those of the first epoch of each
  hardware-clock segment (a new segment starts when
  ``HardwareClockDiscontinuityCount`` changes), so the receiver clock error
  stays continuous within a segment and is estimated by the positioning.
- Transmit time: ``ReceivedSvTimeNanos`` (GPS time of week of the
  satellite's clock when the TOW is decoded).
- ``pseudorange = c * (t_rx - t_tx) * 1e-9`` [m], with a week roll-over
  correction (``t_rx - t_tx`` taken modulo one week into
  ``(-half week, half week]``).
- ``sigma = c * ReceivedSvTimeUncertaintyNanos * 1e-9`` [m].

Which measurements are kept
---------------------------
- ``ConstellationType == 1`` (GPS) only;
- ``State`` has ``STATE_TOW_DECODED`` (0x8) or ``STATE_TOW_KNOWN`` (0x4000):
  without a decoded time of week ``ReceivedSvTimeNanos`` is ambiguous;
- ``ReceivedSvTimeUncertaintyNanos <= max_sv_time_uncertainty_ns`` (default
  500 ns, i.e. 150 m: a measurement the chip itself does not trust to better
  than that is not a usable pseudorange);
- ``FullBiasNanos`` present and non-zero (otherwise the receiver time is not
  GPS time).

The size of the pseudorange is not checked here (the positioning sees
outliers in its residuals).

Rejected measurements are counted per reason in ``rejected``.

Malformed rows (a ``Raw`` row whose field count differs from the header's,
text in a numeric field, a missing required value), a missing ``# Raw``
header or a header without a required column raise
:class:`~mixnav.errors.DataError` naming the file and the line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data import RawPseudoranges
from ..errors import DataError
from ..gnss.geometry import C_LIGHT
from .registry import ReadOptions, register_reader

NS_PER_WEEK = 604_800 * 1_000_000_000
STATE_TOW_DECODED = 0x8
STATE_TOW_KNOWN = 0x4000
CONSTELLATION_GPS = 1

_INT_COLS = ("TimeNanos", "FullBiasNanos", "Svid", "State", "ReceivedSvTimeNanos", "ConstellationType",
             "HardwareClockDiscontinuityCount")
_FLOAT_COLS = ("BiasNanos", "TimeOffsetNanos", "ReceivedSvTimeUncertaintyNanos", "Cn0DbHz")
_REQUIRED = ("TimeNanos", "FullBiasNanos", "Svid", "State", "ReceivedSvTimeNanos",
             "ReceivedSvTimeUncertaintyNanos", "ConstellationType")


#: the one raw-GNSS type (fields: mixnav.data.RawPseudoranges); Android gives cn0, sigma and time_nanos
AndroidPseudoranges = RawPseudoranges


def _parse_int(text: str, name: str, path, lineno: int) -> int:
    t = text.strip()
    try:
        return int(t)
    except ValueError:
        pass
    try:
        v = float(t)
    except ValueError:
        raise DataError(f"column {name}: {t!r} is not a number", file=str(path), line=lineno) from None
    if not np.isfinite(v) or v != int(v) or abs(v) > 2**53:
        raise DataError(f"column {name}: {t!r} is not an integer", file=str(path), line=lineno)
    return int(v)


def _parse_float(text: str, name: str, path, lineno: int) -> float:
    t = text.strip()
    try:
        v = float(t)
    except ValueError:
        raise DataError(f"column {name}: {t!r} is not a number", file=str(path), line=lineno) from None
    if not np.isfinite(v):
        raise DataError(f"column {name}: {t!r} is not finite", file=str(path), line=lineno)
    return v


def read_gnsslogger(path, max_sv_time_uncertainty_ns: float = 500.0) -> AndroidPseudoranges:
    """Read the ``Raw`` rows of a GnssLogger file into GPS pseudoranges.

    Parameters
    ----------
    path : str or Path
    max_sv_time_uncertainty_ns : float
        Measurements with a larger ``ReceivedSvTimeUncertaintyNanos`` are
        rejected [ns].

    Raises
    ------
    DataError
        Missing file, no ``# Raw`` header before the first ``Raw`` row, a
        required column missing from the header, a malformed row (file and
        line named), or no usable GPS measurement.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("Android GnssLogger file not found", file=str(path))
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise DataError(f"cannot read: {exc}", file=str(path)) from exc
    cols: dict[str, int] | None = None
    n_fields = 0
    rows: list[dict] = []
    for lineno, line in enumerate(lines, start=1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s.lstrip("#").strip()
            if body.startswith("Raw,"):
                names = [c.strip() for c in body.split(",")]
                cols = {n: i for i, n in enumerate(names)}
                n_fields = len(names)
                missing = [c for c in _REQUIRED if c not in cols]
                if missing:
                    raise DataError(f"the '# Raw' header lacks column(s) {', '.join(missing)}",
                                    file=str(path), line=lineno)
            continue
        if not s.startswith("Raw,"):
            continue
        if cols is None:
            raise DataError("a 'Raw' row before any '# Raw,...' header naming the columns "
                            "(is this a GnssLogger file?)", file=str(path), line=lineno)
        fields = line.split(",")
        if len(fields) != n_fields:
            raise DataError(f"{len(fields)} fields, the '# Raw' header names {n_fields}",
                            file=str(path), line=lineno)
        row: dict = {"line": lineno}
        # a column absent from the header is absent from the row (optional ones default below)
        for name in _INT_COLS:
            if name in cols:
                t = fields[cols[name]]
                if t.strip() == "":
                    if name in _REQUIRED:
                        raise DataError(f"column {name} is empty", file=str(path), line=lineno)
                    row[name] = 0
                else:
                    row[name] = _parse_int(t, name, path, lineno)
        for name in _FLOAT_COLS:
            if name in cols:
                t = fields[cols[name]]
                if t.strip() == "":
                    if name in _REQUIRED:
                        raise DataError(f"column {name} is empty", file=str(path), line=lineno)
                    row[name] = np.nan if name == "Cn0DbHz" else 0.0
                else:
                    row[name] = _parse_float(t, name, path, lineno)
        rows.append(row)
    if cols is None:
        raise DataError("no '# Raw,...' header and no 'Raw' rows: not a GnssLogger raw-measurement log",
                        file=str(path))
    return _pseudoranges(rows, path, max_sv_time_uncertainty_ns)


def _pseudoranges(rows: list[dict], path: Path, max_unc_ns: float) -> AndroidPseudoranges:
    rejected: dict[str, int] = {}

    def reject(reason):
        rejected[reason] = rejected.get(reason, 0) + 1

    kept = []
    all_epochs = {r["TimeNanos"] for r in rows}
    for r in rows:
        if r["ConstellationType"] != CONSTELLATION_GPS:
            reject("not GPS")
        elif r["FullBiasNanos"] == 0:
            reject("no FullBiasNanos")
        elif not (r["State"] & (STATE_TOW_DECODED | STATE_TOW_KNOWN)):
            reject("time of week not decoded")
        elif r["ReceivedSvTimeUncertaintyNanos"] > max_unc_ns:
            reject("ReceivedSvTimeUncertaintyNanos too large")
        else:
            kept.append(r)
    if not kept:
        raise DataError(f"no usable GPS measurement (rejected: {rejected or 'no Raw rows'})", file=str(path))
    epochs_t: list[int] = []
    week_l, tow_l, epoch_l, prn_l, pr_l, sig_l, cn0_l = [], [], [], [], [], [], []
    seg_count = None
    full0 = bias0 = 0
    for r in kept:
        if r["HardwareClockDiscontinuityCount"] != seg_count:        # new hardware-clock segment
            seg_count = r["HardwareClockDiscontinuityCount"]
            full0, bias0 = r["FullBiasNanos"], r.get("BiasNanos", 0.0)
        if not epochs_t or r["TimeNanos"] != epochs_t[-1]:
            epochs_t.append(r["TimeNanos"])
            week = (-full0) // NS_PER_WEEK
            t_ns = r["TimeNanos"] - full0 - week * NS_PER_WEEK          # exact integer
            week_l.append(week)
            tow_l.append((t_ns - bias0) * 1e-9)
        week = (-full0) // NS_PER_WEEK
        t_rx_int = r["TimeNanos"] - full0 - week * NS_PER_WEEK          # ns of week, integer
        dt_int = (t_rx_int - r["ReceivedSvTimeNanos"]) % NS_PER_WEEK     # travel time, roll-over folded
        if dt_int > NS_PER_WEEK // 2:
            dt_int -= NS_PER_WEEK
        dt_ns = dt_int + r.get("TimeOffsetNanos", 0.0) - bias0
        epoch_l.append(len(epochs_t) - 1)
        prn_l.append(r["Svid"])
        pr_l.append(C_LIGHT * dt_ns * 1e-9)
        sig_l.append(C_LIGHT * r["ReceivedSvTimeUncertaintyNanos"] * 1e-9)
        cn0_l.append(r.get("Cn0DbHz", np.nan))
    tn = np.array(epochs_t, dtype=np.int64)
    # a satellite twice in one epoch: a duplicated row or epoch (docs/validation.md)
    seen: dict[tuple, int] = {}
    for r, e in zip(kept, epoch_l):
        key = (e, r["Svid"])
        if key in seen:
            raise DataError(f"GPS PRN {r['Svid']} measured twice in the epoch of TimeNanos {r['TimeNanos']} "
                            f"(first at line {seen[key]}): a duplicated row or epoch", file=str(path), line=r["line"])
        seen[key] = r["line"]
    if np.any(np.diff(tn) <= 0):
        k = int(np.flatnonzero(np.diff(tn) <= 0)[0]) + 1
        line = next(r["line"] for r in kept if r["TimeNanos"] == tn[k])
        raise DataError("TimeNanos does not increase (epochs out of order or repeated after others)",
                        file=str(path), line=line)
    return AndroidPseudoranges(week=np.array(week_l, dtype=np.int64), tow=np.array(tow_l), time_nanos=tn,
                               epoch=np.array(epoch_l, dtype=np.int64), prn=np.array(prn_l, dtype=np.int64),
                               pseudorange=np.array(pr_l), sigma=np.array(sig_l), cn0=np.array(cn0_l),
                               rejected=rejected, source=str(path),
                               epochs_all_rejected=len(all_epochs - set(epochs_t)))


@register_reader("raw-gnss", "android-gnsslogger")
def _read(path: Path, options: ReadOptions) -> RawPseudoranges:
    """The registered reader (``options``: ``max_sv_time_uncertainty`` [s] of ``[raw_gnss]``)."""
    limit = options.get("max_sv_time_uncertainty")
    return read_gnsslogger(path) if limit is None else read_gnsslogger(path, max_sv_time_uncertainty_ns=limit * 1e9)
