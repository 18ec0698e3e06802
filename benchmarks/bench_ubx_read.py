"""Reading a u-blox log (UBX-RXM-RAWX): mixnav.io.ubx, numpy and pyubx2 decoding, against
the RINEX reader on the same observations.

    python benchmarks/bench_ubx_read.py [--data DIR] [--repeat N]

The log: the 986 epochs of urbannav-tst-static/2020_06_03_TST_03.obs (RINEX 3.02 mixed,
u-blox F9P via RTKCONV) in DIR (default ../shared/data), both signals of every system,
written back as RXM-RAWX messages by pyubx2's own generator (tests/ubx_messages.py), each
followed by a NAV-PVT, an NMEA sentence and junk bytes. Timed, best of N (default 2; wall and
CPU time of this process):

* :func:`mixnav.io.ubx.read_ubx` with every system (``GRECJ``) and with GPS alone, the
  RXM-RAWX payloads decoded by numpy (the default);
* the same with ``decode="pyubx2"`` (every message parsed by ``UBXReader.parse``);
* :func:`mixnav.io.rinex_obs.read_rinex_obs` of the RINEX file, every system.

Then checks that the log reads back as the RINEX file (systems, PRNs, signals, times,
pseudoranges, carrier, Doppler at float32, C/N0, loss-of-lock indicators). Writes
benchmarks/results/ubx_read.md.
"""

from __future__ import annotations

import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))          # tests.ubx_messages: the log writer the tests use

from mixnav.gnss.multi_ephemeris import MultiEphemeris  # noqa: E402
from mixnav.io.rinex_obs import read_rinex_obs  # noqa: E402
from mixnav.io.ubx import read_ubx  # noqa: E402
from tests.ubx_messages import log_bytes, rows_of  # noqa: E402
from _timing import best_wall_cpu as timed  # benchmarks/ is on sys.path

FILE = ("urbannav-tst-static", "2020_06_03_TST_03.obs")
L2 = {"G": "C2L", "R": "C2C", "E": "C7Q", "C": "C7I", "J": "C2L"}


def check(u, r) -> int:
    """AssertionError unless the u-blox read ``u`` is the RINEX read ``r``; the values compared."""
    for f in ("week", "tow", "epoch", "system", "prn", "pseudorange", "cn0", "lli"):
        np.testing.assert_array_equal(getattr(u, f), getattr(r, f), err_msg=f)
    np.testing.assert_array_equal(u.signal, np.where(r.signal == "C1I", "C2I", r.signal))
    np.testing.assert_array_equal(u.carrier, r.carrier)
    np.testing.assert_array_equal(u.doppler, r.doppler.astype(np.float32))
    return int(sum(np.isfinite(getattr(u, f)).sum() for f in ("pseudorange", "carrier", "doppler", "cn0")))


def main() -> None:
    data = Path(sys.argv[sys.argv.index("--data") + 1]) if "--data" in sys.argv else ROOT.parent / "shared" / "data"
    repeat = int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 2
    path = data.joinpath(*FILE)
    l1 = read_rinex_obs(path, systems="GRECJ")
    l2 = read_rinex_obs(path, systems="GRECJ", signals=L2)
    channels = MultiEphemeris.from_rinex(path.with_name("hksc155c.20g"))["R"].channels()
    t0 = time.perf_counter()
    log = log_bytes(rows_of([l1, l2], channels))
    t_gen = time.perf_counter() - t0
    print(f"wrote the log ({len(log) / 1e6:.1f} MB) in {t_gen:.0f} s", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        ubx = Path(tmp) / "tst.ubx"
        ubx.write_bytes(log)
        rows = []
        outs = {}
        for label, fn in (("`read_ubx`, systems GRECJ (numpy decoding, the default)",
                           lambda: read_ubx(ubx, systems="GRECJ")),
                          ("`read_ubx`, GPS (default)", lambda: read_ubx(ubx)),
                          ("`read_ubx`, systems GRECJ, `decode=\"pyubx2\"`",
                           lambda: read_ubx(ubx, systems="GRECJ", decode="pyubx2")),
                          ("`read_rinex_obs` of the RINEX file, systems GRECJ",
                           lambda: read_rinex_obs(path, systems="GRECJ"))):
            wall, cpu, out = timed(fn, repeat)
            rows.append((label, wall, cpu))
            outs[label] = out
            print(f"{label}: {wall:.3f} s wall, {cpu:.3f} s CPU", flush=True)
    u = outs[rows[0][0]]
    n_equal = check(u, l1)
    check(outs[rows[2][0]], l1)
    per_system = {s: int((u.system == s).sum()) for s in "GRECJ"}
    lines = ["# Reading a u-blox log (UBX-RXM-RAWX)", "",
             f"`python benchmarks/bench_ubx_read.py` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC; best of "
             f"{repeat} calls each, wall clock and CPU time of the process; a 2-core machine shared with other "
             "jobs).", "",
             f"Log: the {len(u)} epochs of `{'/'.join(FILE)}` (u-blox F9P via RTKCONV, both signals of every "
             f"system) written back as RXM-RAWX messages by pyubx2's generator (`tests/ubx_messages.py`, "
             f"{t_gen:.0f} s to write), each followed by a NAV-PVT, an NMEA sentence and 8 junk bytes: "
             f"{len(log) / 1e6:.1f} MB, {len(u) * 4} messages. Measurements read with every system: "
             + ", ".join(f"{s} {n}" for s, n in per_system.items()) + ".", "",
             "| reader | wall [s] | CPU [s] | epochs / s (wall) |", "|---|---:|---:|---:|"]
    lines += [f"| {label} | {wall:.3f} | {cpu:.3f} | {len(u) / wall:.0f} |" for label, wall, cpu in rows]
    lines += ["", f"Values equal: {n_equal} pseudorange, carrier, Doppler and C/N0 values of each system's default "
              "signal are the RINEX reader's (Doppler at the float32 RXM-RAWX carries; BeiDou B1I named C2I, "
              "RINEX 3.02's C1I), as are the times to the ns, systems, PRNs and loss-of-lock indicators; the "
              "pyubx2 decoding gives the same values.", "",
              "Where the time goes: pyubx2's `UBXReader` frames the messages (a few reads per message) and "
              "its pure-Python `calc_checksum` checks every UBX frame: about 0.1 s of the numpy path here; the "
              "RXM-RAWX payloads are then one numpy structured array (16-byte header, 32-byte blocks). "
              "`UBXReader.parse` builds one Python attribute per field and block, some 3 ms per 50-measurement "
              "message here.", ""]
    out = Path(__file__).resolve().parent / "results" / "ubx_read.md"
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
