"""Android GnssLogger reader (io/android.py) and SPP on the real log."""

import numpy as np
import pytest

from mixnav.errors import DataError
from mixnav.gnss.geometry import C_LIGHT
from mixnav.io.android import NS_PER_WEEK, read_gnsslogger

from .conftest import data_file

HEADER = ("# Raw,ElapsedRealtimeMillis,TimeNanos,LeapSecond,TimeUncertaintyNanos,FullBiasNanos,BiasNanos,"
          "BiasUncertaintyNanos,DriftNanosPerSecond,DriftUncertaintyNanosPerSecond,"
          "HardwareClockDiscontinuityCount, Svid,TimeOffsetNanos,State,ReceivedSvTimeNanos,"
          "ReceivedSvTimeUncertaintyNanos,Cn0DbHz,PseudorangeRateMetersPerSecond,"
          "PseudorangeRateUncertaintyMetersPerSecond,ConstellationType")
WEEK = 1903


def _raw(time_nanos, full_bias, bias, svid, sv_time, unc=10, state=15, const=1, offset=0.0, disc=7):
    return (f"Raw,1,{time_nanos},,,{full_bias},{bias},1.0,0.0,1.0,{disc},{svid},{offset},{state},{sv_time},"
            f"{unc},35.0,0.0,0.1,{const}")


def _write(tmp_path, lines, name="log.txt"):
    f = tmp_path / name
    f.write_text("# \n# Version: test\n" + "\n".join(lines) + "\n")
    return f


def test_pseudorange_convention(tmp_path):
    # receiver at tow = 100.5 s of week 1903 when TimeNanos = 5 s (bias 0.25 ns)
    time_nanos = 5_000_000_000
    full_bias = -(WEEK * NS_PER_WEEK + 100_500_000_000 - time_nanos)
    sv_time = 100_500_000_000 - 70_000_000            # sent 70 ms earlier
    lines = [HEADER, _raw(time_nanos, full_bias, 0.25, 5, sv_time),
             _raw(time_nanos, full_bias, 0.25, 7, sv_time - 3_000_000, offset=2.0),
             "Fix,gps,37.4,-122.0,-30.0,0.0,3.0,1467321969000",
             _raw(time_nanos + 1_000_000_000, full_bias - 3, 0.5, 5, sv_time + 1_000_000_000 + 1)]
    a = read_gnsslogger(_write(tmp_path, lines))
    assert len(a) == 2 and a.week.tolist() == [WEEK, WEEK]
    assert a.tow == pytest.approx([100.5 - 0.25e-9, 101.5 - 0.25e-9], abs=1e-12)
    assert a.epoch.tolist() == [0, 0, 1] and a.prn.tolist() == [5, 7, 5]
    expected = C_LIGHT * 1e-9 * np.array([70_000_000 - 0.25, 73_000_000 + 2.0 - 0.25, 70_000_000 - 1 - 0.25])
    # the full bias of the first epoch is kept (Google's convention): epoch 2's -3 ns is clock error
    assert a.pseudorange == pytest.approx(expected, abs=1e-6)
    assert a.sigma == pytest.approx([C_LIGHT * 10e-9] * 3)


def test_week_rollover(tmp_path):
    time_nanos = 1_000_000_000
    full_bias = -(WEEK * NS_PER_WEEK + 30_000_000 - time_nanos)   # tow 0.03 s of week 1903
    sv_time = NS_PER_WEEK - 20_000_000                             # 604799.98 s of week 1902
    a = read_gnsslogger(_write(tmp_path, [HEADER, _raw(time_nanos, full_bias, 0.0, 3, sv_time)]))
    assert a.pseudorange[0] == pytest.approx(C_LIGHT * 0.05, abs=1e-6)


def test_hardware_clock_discontinuity_resets_bias(tmp_path):
    t0, fb = 5_000_000_000, -(WEEK * NS_PER_WEEK + 95_000_000_000)
    sv = 100_000_000_000 - 70_000_000
    lines = [HEADER, _raw(t0, fb, 0.0, 5, sv, disc=1),
             _raw(t0 + 10**9, fb - 1000, 0.0, 5, sv + 10**9, disc=2)]
    a = read_gnsslogger(_write(tmp_path, lines))
    # new segment: its own full bias is used, so the second pseudorange carries +1000 ns
    assert a.pseudorange[1] - a.pseudorange[0] == pytest.approx(C_LIGHT * 1000e-9, abs=1e-6)


def test_rejections_are_counted(tmp_path):
    t0, fb = 5_000_000_000, -(WEEK * NS_PER_WEEK + 95_000_000_000)
    sv = 100_000_000_000 - 70_000_000
    lines = [HEADER, _raw(t0, fb, 0.0, 5, sv), _raw(t0, fb, 0.0, 6, sv, const=3),
             _raw(t0, fb, 0.0, 8, sv, state=1), _raw(t0, fb, 0.0, 9, sv, unc=900),
             _raw(t0, fb, 0.0, 10, sv, state=0x4000 | 1)]
    a = read_gnsslogger(_write(tmp_path, lines))
    assert a.prn.tolist() == [5, 10]
    assert a.rejected == {"not GPS": 1, "time of week not decoded": 1, "ReceivedSvTimeUncertaintyNanos too large": 1}
    b = read_gnsslogger(_write(tmp_path, lines, "b.txt"), max_sv_time_uncertainty_ns=1000.0)
    assert 9 in b.prn.tolist()


@pytest.mark.parametrize("bad, message, line", [
    ("Raw,1,2,3", "fields", 4),
    (_raw(5_000_000_000, "abc", 0.0, 5, 1), "FullBiasNanos: 'abc' is not a number", 4),
    (_raw(5_000_000_000, -1, 0.0, 5, 1).replace(",10,35.0", ",x,35.0"), "ReceivedSvTimeUncertaintyNanos", 4),
    (_raw(5_000_000_000, -1, 0.0, "", 1), "Svid is empty", 4),
    (_raw(5_000_000_000, -1, 0.0, 5, "1.5"), "not an integer", 4),
])
def test_malformed_rows(tmp_path, bad, message, line):
    f = _write(tmp_path, [HEADER, bad])
    with pytest.raises(DataError, match=message) as ei:
        read_gnsslogger(f)
    assert ei.value.line == line and "log.txt" in str(ei.value)


def test_missing_header_and_columns(tmp_path):
    f = _write(tmp_path, [_raw(5, -1, 0.0, 5, 1)])
    with pytest.raises(DataError, match="before any '# Raw") as ei:
        read_gnsslogger(f)
    assert ei.value.line == 3
    f = _write(tmp_path, [HEADER.replace(",State,", ",Foo,")], "h.txt")
    with pytest.raises(DataError, match="lacks column.*State"):
        read_gnsslogger(f)
    f = _write(tmp_path, ["hello", "world"], "t.txt")
    with pytest.raises(DataError, match="not a GnssLogger"):
        read_gnsslogger(f)
    with pytest.raises(DataError, match="not found"):
        read_gnsslogger(tmp_path / "absent.txt")
    with pytest.raises(DataError, match="no usable GPS measurement"):
        read_gnsslogger(_write(tmp_path, [HEADER], "empty.txt"))


def test_time_going_backwards(tmp_path):
    fb = -(WEEK * NS_PER_WEEK + 95_000_000_000)
    lines = [HEADER, _raw(6_000_000_000, fb, 0.0, 5, 10**11), _raw(5_000_000_000, fb, 0.0, 5, 10**11)]
    with pytest.raises(DataError, match="TimeNanos does not increase") as ei:
        read_gnsslogger(_write(tmp_path, lines))
    assert ei.value.line == 5


# ---------------------------------------------------------------- real data
LOG = ("android-static", "pseudoranges_log_2016_06_30_21_26_07.txt")


def test_real_log():
    a = read_gnsslogger(data_file(*LOG))
    assert len(a) == 223 and a.week[0] == WEEK
    assert len(a.prn) + sum(a.rejected.values()) == 1379                # every Raw row accounted for
    dt = np.diff(a.tow)
    assert np.all((dt > 0.9) & (dt < 1.5)) and np.median(dt) == pytest.approx(1.0, abs=0.01)  # ~1 Hz
    # GPS ranges from the ground: 20000-26000 km (plus the receiver clock error)
    assert np.all((a.pseudorange > 1.9e7) & (a.pseudorange < 2.7e7))


def test_real_spp_near_surveyed_point():
    from mixnav.geodesy.frames import ecef_to_lla, lla_to_ned
    from mixnav.gnss.ephemeris import BroadcastEphemeris
    from mixnav.gnss.spp import solve_epochs

    a = read_gnsslogger(data_file(*LOG))
    eph = BroadcastEphemeris.from_rinex(data_file("android-static", "hour1820.16n"))
    track = solve_epochs(eph, a.week, a.tow, a.epoch, a.prn, a.pseudorange)
    assert track.ok.all()
    ref = np.array([np.deg2rad(37.422578), np.deg2rad(-122.081678), -28.0])
    ned = lla_to_ned(ecef_to_lla(track.pos_ecef), ref)
    # a phone's SPP: horizontal within tens of metres; far from the 1e3-1e6 m of a wrong clock or time
    assert np.sqrt(np.mean(ned[:, 0] ** 2 + ned[:, 1] ** 2)) < 20.0
    assert np.abs(np.median(ned, axis=0)).max() < 15.0
