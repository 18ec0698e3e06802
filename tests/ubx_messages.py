"""UBX-RXM-RAWX messages built with pyubx2's own generator (``UBXMessage(..., GET, **fields)``
with its repeated groups ``prMes_01``...), from observations read from a RINEX file: what
tests/test_ubx.py and benchmarks/bench_ubx_read.py write as a u-blox log.

The lock time of each signal is made from the RINEX loss-of-lock bit 0 of its carrier
(0 ms where the bit is set, else growing by the time since the signal's previous epoch,
held at 64500 ms), so that :func:`mixnav.io.ubx.loss_of_lock` gives the bit back;
``trkStat``: pseudorange valid, carrier valid where the carrier is not blank, half cycle
valid where LLI bit 1 is clear.
"""

from __future__ import annotations

import numpy as np

#: RINEX system letter -> UBX gnssId
GNSS_ID = {"G": 0, "E": 2, "C": 3, "J": 5, "R": 6}
#: (letter, RINEX code) -> UBX sigId (BeiDou B1I/B2I: D1; the GEO satellites C01-C05 D2)
SIG_ID = {("G", "C1C"): 0, ("G", "C2L"): 3, ("G", "C2S"): 4, ("R", "C1C"): 0, ("R", "C2C"): 2,
          ("E", "C1C"): 0, ("E", "C1B"): 1, ("E", "C7Q"): 6, ("E", "C7I"): 5, ("E", "C5Q"): 4,
          ("C", "C2I"): 0, ("C", "C1I"): 0, ("C", "C7I"): 2, ("J", "C1C"): 0, ("J", "C2L"): 5}


def rows_of(obs_list, channels=None):
    """Per epoch (in time order), the measurement dicts of every read in ``obs_list``
    (RawPseudoranges of the same file, each with other signals): (week, tow, [dict])."""
    channels = channels or {}
    out = {}
    lock: dict = {}
    for obs in obs_list:
        for i in range(len(obs.prn)):
            e = int(obs.epoch[i])
            s, code, prn = str(obs.system[i]), str(obs.signal[i]), int(obs.prn[i])
            sig = SIG_ID[(s, code)] + (1 if s == "C" and prn <= 5 else 0)
            out.setdefault((int(obs.week[e]), round(float(obs.tow[e]) * 1e9)), []).append(dict(
                gnssId=GNSS_ID[s], svId=prn, sigId=sig, freqId=channels.get(prn, 0) + 7 if s == "R" else 0,
                prMes=float(obs.pseudorange[i]),
                cpMes=0.0 if not np.isfinite(obs.carrier[i]) else float(obs.carrier[i]),
                doMes=float(obs.doppler[i]), cno=int(obs.cn0[i]),
                cpValid=int(np.isfinite(obs.carrier[i])), lli=int(obs.lli[i, 1]), key=(s, prn, sig)))
    epochs = []
    for (week, tow_ns), meas in sorted(out.items()):
        t = week * 604800 * 10**9 + tow_ns
        for m in meas:
            prev = lock.get(m["key"])
            if m["lli"] & 1:
                lt = 0
            elif prev is None:
                lt = 5000
            else:
                lt = min(prev[1] + (t - prev[0]) // 10**6, 64500)
            lock[m["key"]] = (t, lt)
            m["locktime"] = lt
        epochs.append((week, tow_ns / 1e9, meas))
    return epochs


def rawx(week, tow, meas, leap=18, leap_known=1):
    """One RXM-RAWX UBXMessage (pyubx2's generator) of the measurement dicts ``meas``."""
    from pyubx2 import GET, UBXMessage
    kw = dict(rcvTow=tow, week=week, leapS=leap, numMeas=len(meas), leapSec=leap_known, version=1)
    for j, m in enumerate(meas, 1):
        s = f"_{j:02d}"
        for k in ("prMes", "cpMes", "doMes", "gnssId", "svId", "sigId", "freqId", "locktime", "cno"):
            kw[k + s] = m[k]
        kw.update({"prStd" + s: 5, "cpStd" + s: 3, "doStd" + s: 6, "prValid" + s: m.get("prValid", 1),
                   "cpValid" + s: m["cpValid"], "halfCyc" + s: 0 if m["lli"] & 2 else 1, "subHalfCyc" + s: 0})
    return UBXMessage("RXM", "RXM-RAWX", GET, **kw)


def nav_pvt(itow_ms):
    from pyubx2 import GET, UBXMessage
    return UBXMessage("NAV", "NAV-PVT", GET, iTOW=itow_ms, year=2020, month=6, day=3, numSV=20)


#: bytes that are no message (no 0xb5, '$' or 0xd3, which start a UBX, NMEA or RTCM 3 frame)
JUNK = b"\x00\x01junk\xff\x10"
NMEA = b"$GNGGA,030227.00,2218.1234,N,11410.5678,E,1,12,0.9,10.0,M,-2.0,M,,*4B\r\n"


def log_bytes(epochs, extras=True) -> bytes:
    """A u-blox log of the epochs (:func:`rows_of`): each RXM-RAWX followed, when ``extras``,
    by a NAV-PVT, an NMEA sentence and junk bytes."""
    parts = []
    for week, tow, meas in epochs:
        parts.append(rawx(week, tow, meas).serialize())
        if extras:
            parts += [nav_pvt(int(round(tow * 1000))).serialize(), NMEA, JUNK]
    return b"".join(parts)
