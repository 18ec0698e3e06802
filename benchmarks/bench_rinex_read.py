"""Reading a RINEX observation file: georinex against mixnav's own numpy reader.

    python benchmarks/bench_rinex_read.py [--data DIR] [--repeat N]

The file: urbannav-tst-static/2020_06_03_TST_03.obs (RINEX 3.02 mixed, u-blox via
RTKCONV: GPS, GLONASS, Galileo, BeiDou, QZSS, 986 epochs, 3.7 MB) in DIR (default
../shared/data). Timed, best of N (default 2; wall and CPU time of this process):

* georinex ``load(path, fast=False)``: every system and type (the independent reader);
* georinex with ``use={"G"}``: what io.rinex_obs called before (GPS only);
* :func:`mixnav.io.rinex_obs.read_rinex_obs` with every system (``GRECJ``) and with GPS
  alone (the default): the file walked once and every field parsed by numpy.

Then checks, for each system's default signal, that the reader's pseudorange, carrier,
Doppler and C/N0 equal georinex's at every epoch and satellite (tests/test_rinex_multi.py
checks every type of every system). Writes benchmarks/results/rinex_read.md.
"""

from __future__ import annotations

import sys
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from mixnav.gnss.signals import companions
from mixnav.io.rinex_obs import read_rinex_obs
from _timing import best_wall_cpu as timed  # benchmarks/ is on sys.path

FILE = ("urbannav-tst-static", "2020_06_03_TST_03.obs")
GPS0 = np.datetime64("1980-01-06T00:00:00", "ns")


def georinex_load(path, use=None):
    import georinex
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return georinex.load(path, use=use, fast=False)


def same_values(r, g) -> int:
    """Compare the reader's rows with georinex's dataset ``g``; the number of values equal
    (AssertionError at the first that is not)."""
    gt = np.asarray(g.time.values).astype("datetime64[ns]")
    svs = [str(x) for x in g.sv.values]
    t = GPS0 + (r.week.astype(np.int64) * 604800 * 10**9 + np.round(r.tow * 1e9).astype(np.int64)) \
        .astype("timedelta64[ns]")
    i = np.searchsorted(gt, t[r.epoch], side="right") - 1      # georinex keeps us, truncated
    assert ((t[r.epoch] - gt[i]).astype(np.int64) < 2000).all()
    j = np.array([svs.index(x) for x in r.satellite_ids()])
    n = 0
    for sig in np.unique(r.signal):
        rows = r.signal == sig
        for name, typ in zip(("pseudorange", "carrier", "doppler", "cn0"), (sig, *companions(sig))):
            ours = getattr(r, name)[rows]
            theirs = g[typ].values[i[rows], j[rows]]
            np.testing.assert_array_equal(ours, theirs, err_msg=f"{sig} {name}")
            n += int(np.isfinite(ours).sum())
    return n


def main() -> None:
    data = Path(sys.argv[sys.argv.index("--data") + 1]) if "--data" in sys.argv else \
        Path(__file__).resolve().parents[2] / "shared" / "data"
    repeat = int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 2
    path = data.joinpath(*FILE)
    rows = []
    g_all = None
    for label, fn in (("georinex, every system", lambda: georinex_load(path)),
                      ("georinex, GPS only (`use={'G'}`, the reader before)", lambda: georinex_load(path, {"G"})),
                      ("mixnav `read_rinex_obs`, systems GRECJ", lambda: read_rinex_obs(path, systems="GRECJ")),
                      ("mixnav `read_rinex_obs`, GPS (default)", lambda: read_rinex_obs(path))):
        wall, cpu, out = timed(fn, repeat)
        rows.append((label, wall, cpu))
        print(f"{label}: {wall:.3f} s wall, {cpu:.3f} s CPU", flush=True)
        if label.startswith("georinex, every"):
            g_all = out
    every = read_rinex_obs(path, systems="GRECJ")
    n_equal = same_values(every, g_all)
    per_system = {s: int((every.system == s).sum()) for s in "GRECJ"}
    base_wall, base_cpu = rows[0][1], rows[0][2]
    lines = ["# Reading a RINEX observation file: georinex against mixnav's own reader", "",
             f"`python benchmarks/bench_rinex_read.py` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC; "
             f"best of {repeat} calls each, wall clock and CPU time of the process; a 2-core machine shared with "
             "other jobs).", "",
             f"File: `{'/'.join(FILE)}` (RINEX 3.02 mixed, u-blox via RTKCONV, "
             f"{path.stat().st_size / 1e6:.1f} MB, {len(every)} epochs; measurements read with every system: "
             + ", ".join(f"{s} {n}" for s, n in per_system.items()) + ").", "",
             "| reader | wall [s] | CPU [s] | georinex (every system) / this, wall | ... CPU |",
             "|---|---:|---:|---:|---:|"]
    lines += [f"| {label} | {wall:.3f} | {cpu:.3f} | {base_wall / wall:.0f} | {base_cpu / cpu:.0f} |"
              for label, wall, cpu in rows]
    lines += ["", f"Values equal: {n_equal} pseudorange, carrier, Doppler and C/N0 values of each system's default "
              f"signal ({', '.join(sorted(set(every.signal)))}) are georinex's, exactly, at every epoch and "
              "satellite (every type of every system: tests/test_rinex_multi.py, the whole file under `-m slow`).",
              "", "Why the difference: georinex parses each epoch with `numpy.genfromtxt` and merges one xarray "
              "Dataset per epoch; mixnav walks the file's lines once (the walk it needs anyway to count and "
              "name every record) and parses all fields at once as fixed-width bytes (an `F14.3` field is its "
              "integer of thousandths / 1000, the same double as `float` of the text).", ""]
    out = Path(__file__).resolve().parent / "results" / "rinex_read.md"
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
