"""Seeded fuzzing of every reader on copies of the real files (issue 22; docs/validation.md).

Each case takes a copy of a real file (or a slice of it, to keep the cases
fast), damages it once (truncation at a random byte, random byte flips, or
lines swapped, duplicated or deleted) and reads it. A reader may accept the
copy or refuse it with a :class:`~mixnav.errors.MixnavError` (which names the
file); anything else (a traceback), a hang, or a NaN/infinity in what it
returns is a failure. Skipped without the shared data.
"""

from __future__ import annotations

import dataclasses
import shutil
import signal
import warnings
from pathlib import Path

import numpy as np
import pytest

from mixnav.errors import MixnavError

from .conftest import DATA_DIR

#: seconds any one read may take before it counts as a hang
CASE_TIMEOUT_S = 10


# ----------------------------------------------------------------------------- mutations

def truncate(b: bytes, rng) -> bytes:
    return b[: int(rng.integers(0, len(b) + 1))]


def flip(b: bytes, rng) -> bytes:
    a = bytearray(b)
    for _ in range(int(rng.integers(1, 9))):
        k = int(rng.integers(0, len(a)))
        a[k] = int(rng.choice([rng.integers(0, 256), ord(rng.choice(list("0123456789-.,eE \n\tnaNiIf")))]))
    return bytes(a)


def shuffle_lines(b: bytes, rng) -> bytes:
    lines = b.split(b"\n")
    if len(lines) < 3:
        return flip(b, rng)
    op = rng.integers(0, 3)
    i, j = (int(x) for x in rng.integers(0, len(lines), 2))
    if op == 0:
        lines[i], lines[j] = lines[j], lines[i]
    elif op == 1:
        lines.insert(j, lines[i])
    else:
        del lines[i]
    return b"\n".join(lines)


MUTATIONS = (truncate, flip, shuffle_lines)


# ----------------------------------------------------------------------------- checks

def _finite(obj, where="result"):
    """Every float array or number reachable from ``obj`` (dataclasses, tuples, dicts) is finite."""
    if obj is None or isinstance(obj, (str, bytes, bool, int, Path)):
        return
    if isinstance(obj, float):
        assert np.isfinite(obj), f"{where} is {obj}"
        return
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind == "f":
            bad = ~np.isfinite(obj)
            if where.endswith(("cn0", "vel_ned", "sd_vel", "doppler", "carrier", "leap_seconds")) and obj.dtype.kind == "f":
                return   # optional columns: NaN marks "not given" (documented)
            assert not bad.any(), f"{where} has {int(bad.sum())} non-finite values"
        return
    if dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            _finite(getattr(obj, f.name), f"{where}.{f.name}")
    elif isinstance(obj, (tuple, list)):
        for i, x in enumerate(obj):
            _finite(x, f"{where}[{i}]")
    elif isinstance(obj, dict):
        for k, x in obj.items():
            _finite(x, f"{where}.{k}")


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


def _read_once(read, path, what):
    """Read ``path``; a MixnavError is a clean refusal, anything else a failure."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_TIMEOUT_S)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # gap warnings and the like are documented handlings
            out = read(path)
    except MixnavError as exc:
        assert str(exc), what
        return "refused"
    except _Hang:
        pytest.fail(f"{what}: no answer within {CASE_TIMEOUT_S} s (hang)")
    except Exception as exc:  # noqa: BLE001
        pytest.fail(f"{what}: {type(exc).__name__}: {exc} (a traceback instead of a message)")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    _finite(out, what)
    return "read"


# ----------------------------------------------------------------------------- readers

def _head(src: Path, n_lines: int) -> bytes:
    with open(src, "rb") as fh:
        return b"".join(fh.readline() for _ in range(n_lines))


def _drive(tmp: Path):
    """The first 20 s of drive-0708's IMU, its tag cut to match, and the .pos file's first 600 epochs."""
    d = DATA_DIR / "drive-0708"
    csv = _head(d / "imu_1934.csv", 2000)
    tag = (d / "imu_1934.csv.tag").read_bytes()
    ticks = [int(x.split(b",")[6]) for x in csv.splitlines()[1:-1]]
    pairs = np.frombuffer(tag, dtype="<u4", offset=76).reshape(-1, 2)
    keep = int(np.searchsorted(pairs[:, 0], ticks[-1] - ticks[0], side="right"))
    (tmp / "imu.csv").write_bytes(csv)
    (tmp / "imu.csv.tag").write_bytes(tag[:76 + 8 * max(keep, 1)])
    pos = d / "gnss_1934_sf.pos"
    head = [ln for ln in pos.read_bytes().split(b"\n") if ln.startswith(b"%")]
    body = [ln for ln in pos.read_bytes().split(b"\n") if ln and not ln.startswith(b"%")][:600]
    (tmp / "g.pos").write_bytes(b"\n".join(head + body) + b"\n")


def _generic_from_drive(tmp: Path):
    """The drive's IMU and fixes in the generic CSV layout (docs/data_formats.md)."""
    from mixnav.io.drive0708 import read_drive_imu
    from mixnav.io.rtklib import read_pos
    _drive(tmp)
    imu = read_drive_imu(tmp / "imu.csv", tmp / "imu.csv.tag")
    w, f = imu.dtheta / imu.dt[:, None], imu.dvel / imu.dt[:, None]
    rows = ["time[s],wx[rad/s],wy[rad/s],wz[rad/s],fx[m/s^2],fy[m/s^2],fz[m/s^2]"]
    rows += [f"{t:.4f},{a[0]:.6g},{a[1]:.6g},{a[2]:.6g},{b[0]:.6g},{b[1]:.6g},{b[2]:.6g}"
             for t, a, b in zip(imu.time, w, f)]
    (tmp / "imu_generic.csv").write_text("\n".join(rows) + "\n")
    fx = read_pos(tmp / "g.pos").fixes()
    rows = ["time[s],lat[deg],lon[deg],height[m],sd_n[m],sd_e[m],sd_d[m]"]
    rows += [f"{t:.3f},{np.degrees(p[0]):.9f},{np.degrees(p[1]):.9f},{p[2]:.3f},{s[0]:.4f},{s[1]:.4f},{s[2]:.4f}"
             for t, p, s in zip(fx.time, fx.lla, fx.pos_sigma)]
    (tmp / "gnss_generic.csv").write_text("\n".join(rows) + "\n")


def _rinex_from_android(tmp):
    """A RINEX 3 observation file of the first 40 epochs of the android-static log (written by
    the test, as in tests/test_process_raw.py)."""
    from mixnav.io import android
    from .test_process_raw import _write_rinex3
    a = android.read_gnsslogger(DATA_DIR / "android-static" / "pseudoranges_log_2016_06_30_21_26_07.txt")
    sel = a.epoch < 40
    _write_rinex3(tmp / "o.rnx", a.week[:40], a.tow[:40], a.epoch[sel], a.prn[sel], a.pseudorange[sel])


def _rinex2_from_android(tmp):
    """A RINEX 2.11 observation file of the first 40 epochs of the android-static log with
    GLONASS, Galileo and SBAS records mixed in (tests/test_rinex_obs.py's writer)."""
    from mixnav.io import android
    from .test_rinex_obs import _phone_records, _time, _write_rinex2
    a = android.read_gnsslogger(DATA_DIR / "android-static" / "pseudoranges_log_2016_06_30_21_26_07.txt")
    _write_rinex2(tmp / "o.16o", [_time(a.week[k], a.tow[k]) for k in range(40)], _phone_records(a, 40))


def _multi_nav_states(path):
    """Read a navigation file with MultiEphemeris; every system's states a minute after its first record."""
    from mixnav.gnss.gnss_time import bdt_to_gpst, gpst_week_tow
    from mixnav.gnss.multi_ephemeris import MultiEphemeris
    m = MultiEphemeris.from_rinex(path)
    out = []
    for s, eph in m.systems.items():
        t = eph.rec["week"][0] * 604800.0 + eph.rec["toe"][0] + 60.0
        week, tow = gpst_week_tow(bdt_to_gpst(t) if s == "C" else t)
        out.append(m.states(s, None, week, tow))
    return out


def _urbannav_epochs(tmp):
    """The urbannav RINEX 3.02 mixed file's header and first 15 epochs (5 systems)."""
    lines = (DATA_DIR / "urbannav-tst-static" / "2020_06_03_TST_03.obs").read_bytes().splitlines(keepends=True)
    at = [i for i, ln in enumerate(lines) if ln.startswith(b">")]
    (tmp / "u.obs").write_bytes(b"".join(lines[:at[15]]))


def _ubx_from_urbannav(tmp):
    """A u-blox log (RXM-RAWX by pyubx2's generator, NAV-PVT, NMEA and junk between them) of the
    first 15 epochs of the UrbanNav RINEX file (tests/ubx_messages.py)."""
    import dataclasses
    from mixnav.io.rinex_obs import read_rinex_obs
    from .ubx_messages import log_bytes, rows_of
    r = read_rinex_obs(DATA_DIR / "urbannav-tst-static" / "2020_06_03_TST_03.obs", systems="GRECJ")
    k = r.epoch < 15
    r = dataclasses.replace(r, week=r.week[:15], tow=r.tow[:15], **{f: getattr(r, f)[k] for f in (
        "epoch", "prn", "pseudorange", "doppler", "cn0", "system", "signal", "carrier", "lli", "line")})
    (tmp / "u.ubx").write_bytes(log_bytes(rows_of([r], {s: 0 for s in range(1, 25)})))


def _readers():
    from mixnav.config.loader import load_dataset, load_scenario
    from mixnav.io import android, comma2k19, drive0708, generic_csv, psins, rinex_obs, rtklib, smartloc, ubx
    return [
        # name, prepare(tmp), file to damage, read(path), cases
        ("drive-imu", _drive, "imu.csv",
         lambda p: drive0708.read_drive_imu(p, p.with_name("imu.csv.tag")), 45),
        ("drive-tag", _drive, "imu.csv.tag",
         lambda p: drive0708.read_drive_imu(p.with_name("imu.csv"), p), 35),
        ("rtklib-pos", _drive, "g.pos", lambda p: rtklib.read_pos(p).fixes(), 45),
        ("generic-imu", _generic_from_drive, "imu_generic.csv", generic_csv.read_imu_csv, 25),
        ("generic-gnss", _generic_from_drive, "gnss_generic.csv", generic_csv.read_gnss_csv, 25),
        ("psins", lambda t: (t / "l.imu").write_bytes(_head(DATA_DIR / "psins-lasergyro" / "lasergyro.imu", 3000)),
         "l.imu", lambda p: psins.read_psins_imu(p), 30),
        ("android", lambda t: (t / "a.txt").write_bytes(
            _head(DATA_DIR / "android-static" / "pseudoranges_log_2016_06_30_21_26_07.txt", 1500)),
         "a.txt", lambda p: android.read_gnsslogger(p), 40),
        ("rinex-obs", _rinex_from_android, "o.rnx", lambda p: rinex_obs.read_rinex_obs(p), 30),
        ("rinex2-obs", _rinex2_from_android, "o.16o", lambda p: rinex_obs.read_rinex_obs(p), 30),
        *[(f"multi-nav-{ext}", lambda t, ext=ext: shutil.copy(DATA_DIR / "urbannav-tst-static" / f"hksc155c.20{ext}",
                                                               t / f"h.20{ext}"),
           f"h.20{ext}", _multi_nav_states, 20) for ext in "nglb"],


        ("rinex2-obs-multi", _rinex2_from_android, "o.16o", lambda p: rinex_obs.read_rinex_obs(p, systems="GRE"), 30),
        ("rinex3-obs-urbannav", _urbannav_epochs, "u.obs", lambda p: rinex_obs.read_rinex_obs(p, systems="GRECJ"), 30),
        ("ubx", _ubx_from_urbannav, "u.ubx", lambda p: ubx.read_ubx(p, systems="GRECJ"), 30),
        ("smartloc-pr", lambda t: (t / "in.txt").write_bytes(
            _head(DATA_DIR / "smartloc-berlin" / "Berlin_Potsdamer_Platz_Input.txt", 1500)),
         "in.txt", smartloc.read_pseudoranges, 25),
        ("smartloc-gt", lambda t: (t / "gt.txt").write_bytes(
            _head(DATA_DIR / "smartloc-berlin" / "Berlin_Potsdamer_Platz_GT.txt", 800)),
         "gt.txt", smartloc.read_ground_truth, 20),
        ("comma-imu", lambda t: shutil.copytree(DATA_DIR / "comma2k19-example1", t / "seg"),
         "seg/processed_log/IMU/gyro/value", lambda p: comma2k19.read_comma_imu(p.parents[3]), 15),
        ("comma-gnss", lambda t: shutil.copytree(DATA_DIR / "comma2k19-example1", t / "seg"),
         "seg/processed_log/GNSS/live_gnss_ublox/value", lambda p: comma2k19.read_comma_gnss(p.parents[3]), 15),
        ("scenario", lambda t: shutil.copy(Path(load_scenario.__code__.co_filename).parent / "scenarios" /
                                           "loose-demo.toml", t / "s.toml"),
         "s.toml", lambda p: load_scenario(str(p)), 40),
        ("dataset", lambda t: shutil.copy(Path(load_dataset.__code__.co_filename).parent / "datasets" /
                                          "drive-0708-plain.toml", t / "d.toml"),
         "d.toml", lambda p: load_dataset(str(p)), 30),
    ]


@pytest.mark.skipif(not DATA_DIR.is_dir(), reason="shared data not found")
@pytest.mark.parametrize("spec", _readers(), ids=lambda s: s[0])
def test_reader_survives_damaged_copies(tmp_path, spec):
    name, prepare, target, read, cases = spec
    base = tmp_path / "base"
    base.mkdir()
    prepare(base)
    assert _read_once(read, base / target, f"{name} (undamaged)") == "read"
    original = (base / target).read_bytes()
    rng = np.random.default_rng(sum(map(ord, name)))   # seeded per reader
    seen = {"read": 0, "refused": 0}
    for i in range(cases):
        mutate = MUTATIONS[i % len(MUTATIONS)]
        (base / target).write_bytes(mutate(original, rng))
        seen[_read_once(read, base / target, f"{name} case {i} ({mutate.__name__})")] += 1
    print(name, seen)
    assert seen["refused"] > 0   # the damage is noticed at least sometimes
    # no bound on the whole loop's wall time: a hang is caught per case (CASE_TIMEOUT_S), and a
    # sum of times is a timed unit test that a loaded CI machine fails (it did, on multi-nav-g)
