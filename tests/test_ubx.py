"""u-blox logs (UBX-RXM-RAWX) as raw-GNSS observations (issue 36; mixnav.io.ubx).

The round trip: the first 30 epochs of the UrbanNav RINEX file (a u-blox F9P log converted
by RTKLIB) written back as RXM-RAWX messages by pyubx2's own generator, with NAV-PVT, NMEA
and junk bytes between them, must read back as the RINEX reader reads the file.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from mixnav.errors import ArgumentError, ConfigError, DataError
from mixnav.io.imu_checks import DataWarning
from mixnav.io.ubx import LOCK_MAX_MS, loss_of_lock, read_ubx

from .conftest import data_file
from .ubx_messages import JUNK, log_bytes, nav_pvt, rawx, rows_of

OBS = ("urbannav-tst-static", "2020_06_03_TST_03.obs")
#: the second signal of each system in the file
L2 = {"G": "C2L", "R": "C2C", "E": "C7Q", "C": "C7I", "J": "C2L"}
FIELDS = ("epoch", "prn", "pseudorange", "doppler", "cn0", "system", "signal", "carrier", "lli", "line")


def first_epochs(obs, n):
    """The first ``n`` epochs of RawPseudoranges ``obs``."""
    k = obs.epoch < n
    return dataclasses.replace(obs, week=obs.week[:n], tow=obs.tow[:n],
                               **{f: getattr(obs, f)[k] for f in FIELDS if getattr(obs, f) is not None})


@pytest.fixture(scope="module")
def urbannav():
    """The RINEX reads (default signals, second signals) of the first 30 epochs, the GLONASS
    channels of the navigation file, and the u-blox log made of them (bytes)."""
    from mixnav.gnss.multi_ephemeris import MultiEphemeris
    from mixnav.io.rinex_obs import read_rinex_obs
    path = data_file(*OBS)
    l1 = first_epochs(read_rinex_obs(path, systems="GRECJ"), 30)
    l2 = first_epochs(read_rinex_obs(path, systems="GRECJ", signals=L2), 30)
    channels = MultiEphemeris.from_rinex(path.with_name("hksc155c.20g"))["R"].channels()
    return l1, l2, channels, log_bytes(rows_of([l1, l2], channels))


def same_as_rinex(u, r, channels):
    """The u-blox read ``u`` equals the RINEX read ``r`` (BeiDou B1I: RINEX 3.02's C1I is C2I)."""
    assert len(u) == len(r) and len(u.prn) == len(r.prn)
    np.testing.assert_array_equal(u.week, r.week)
    np.testing.assert_array_equal(u.tow, r.tow)              # both to the ns from integer ns
    np.testing.assert_array_equal(u.epoch, r.epoch)
    np.testing.assert_array_equal(u.system, r.system)
    np.testing.assert_array_equal(u.prn, r.prn)
    np.testing.assert_array_equal(u.signal, np.where(r.signal == "C1I", "C2I", r.signal))
    np.testing.assert_array_equal(u.pseudorange, r.pseudorange)                 # prMes R8: exact
    np.testing.assert_array_equal(u.carrier, r.carrier)                         # cpMes R8, NaN where blank
    np.testing.assert_array_equal(u.doppler, r.doppler.astype(np.float32))      # doMes R4
    np.testing.assert_array_equal(u.cn0, r.cn0)                                 # cno U1 (whole dB-Hz here)
    np.testing.assert_array_equal(u.lli, r.lli)                                 # on the carrier, bits 0 and 1
    glo = sorted(set(r.prn[r.system == "R"].tolist()))
    assert u.glonass_channels == {s: channels[s] for s in glo}
    assert np.array_equal(u.leap_seconds, np.full(len(u), 18.0))


def test_round_trip_urbannav(tmp_path, urbannav):
    l1, l2, channels, log = urbannav
    path = tmp_path / "tst.ubx"
    path.write_bytes(log)
    u = read_ubx(path, systems="GRECJ")
    same_as_rinex(u, l1, channels)
    # the other messages counted, the junk bytes too
    assert u.event_records == {"NAV-PVT": 30, "NMEA": 30, "bytes skipped": 30 * len(JUNK)}
    # satellites with the second signal only: counted as RINEX counts records without the first
    assert set(u.rejected) <= {"no C1C pseudorange", "no R C1C pseudorange", "no E C1C/C1X pseudorange",
                               "no C C2I/C1I pseudorange", "no J C1C pseudorange"}
    # the second signals, chosen by signals= as the RINEX reader chooses them
    same_as_rinex(read_ubx(path, systems="GRECJ", signals=L2), l2, channels)
    # GPS alone (the default): GPS rows, the other systems counted
    g = read_ubx(path)
    assert set(g.system) == {"G"} and len(g.prn) == int((l1.system == "G").sum())
    assert {k for k in g.rejected if k.startswith("not GPS")} == {f"not GPS: {s}" for s in "RECJ"}
    # pyubx2's own parser decodes every message to the same values
    p = read_ubx(path, systems="GRECJ", decode="pyubx2")
    for f in FIELDS[:-1] + ("week", "tow", "leap_seconds"):
        np.testing.assert_array_equal(getattr(p, f), getattr(u, f), err_msg=f)
    assert (p.rejected, p.glonass_channels) == (u.rejected, u.glonass_channels)


def test_round_trip_without_extras(tmp_path, urbannav):
    """RXM-RAWX alone, back to back: the same observations, nothing else counted."""
    l1, l2, channels, _ = urbannav
    path = tmp_path / "plain.ubx"
    path.write_bytes(log_bytes(rows_of([l1, l2], channels), extras=False))
    u = read_ubx(path, systems="GRECJ")
    same_as_rinex(u, l1, channels)
    assert u.event_records == {}


def _meas(sv=5, lock=5000, pr=2.2e7, gnss=0, sig=0, **kw):
    m = dict(gnssId=gnss, svId=sv, sigId=sig, freqId=0, prMes=pr, cpMes=1.1e8, doMes=-100.5, cno=40,
             locktime=lock, cpValid=1, lli=0)
    m.update(kw)
    return m


def _write(tmp_path, epochs, name="s.ubx", tail=b""):
    path = tmp_path / name
    path.write_bytes(b"".join(rawx(2108, tow, meas).serialize() for tow, meas in epochs) + tail)
    return path


def test_loss_of_lock_rule():
    # one signal at 1 s epochs: growing, a decrease, a reset to 0, a gap of 5 s with a lock
    # shorter than the gap, one longer than the gap, the 64500 ms ceiling
    t = np.array([0, 1, 2, 3, 4, 9, 14, 15, 16], np.int64) * 10**9
    lock = np.array([800, 1800, 900, 0, 1000, 3000, 6000, LOCK_MAX_MS, LOCK_MAX_MS])
    want = np.array([0, 0, 1, 1, 0, 1, 0, 0, 0], bool)
    np.testing.assert_array_equal(loss_of_lock(np.zeros(len(t)), t, lock), want)
    # the first message of a signal: set only with lock time 0
    assert loss_of_lock(np.zeros(1), np.zeros(1), np.array([0]))[0]
    # per signal, in any row order
    key = np.r_[np.zeros(len(t)), np.ones(len(t))]
    perm = np.random.default_rng(1).permutation(2 * len(t))
    got = loss_of_lock(key[perm], np.r_[t, t][perm], np.r_[lock, lock][perm])
    np.testing.assert_array_equal(got, np.r_[want, want][perm])
    # at 10 Hz, a lock time that decreased though still longer than the 0.1 s since the last message
    assert loss_of_lock(np.zeros(2), np.array([0, 10**8]), np.array([1800, 1500]))[1]
    # a lock 9 ms short of the time since the previous message: within the tolerance
    assert not loss_of_lock(np.zeros(2), np.array([0, 10**9]), np.array([0, 991]))[1]
    assert loss_of_lock(np.zeros(2), np.array([0, 10**9]), np.array([0, 989]))[1]


def test_lli_and_half_cycle_through_the_reader(tmp_path):
    locks = [800, 1800, 900, 2000]
    path = _write(tmp_path, [(100.0 + i, [_meas(lock=lk, lli=2 if i == 3 else 0)]) for i, lk in enumerate(locks)])
    u = read_ubx(path)
    np.testing.assert_array_equal(u.lli[:, 1], [0, 0, 1, 2])   # decrease -> bit 0; half cycle not valid -> bit 1
    assert (u.lli[:, [0, 2, 3]] == 0).all()
    # a carrier flagged not valid: NaN, no half-cycle bit
    u = read_ubx(_write(tmp_path, [(100.0, [_meas(cpValid=0, lli=2)])], "c.ubx"))
    assert np.isnan(u.carrier[0]) and u.lli[0, 1] == 0


def test_times_to_the_ns_and_leap_seconds(tmp_path):
    """rcvTow to the ns (rounded, not truncated: 270147.0000039 s * 1e9 is just below its
    integer), the week as given; leapS NaN where recStat says it is not determined."""
    path = tmp_path / "t.ubx"
    path.write_bytes(rawx(2108, 270147.0000039, [_meas()], leap_known=0).serialize()
                     + rawx(2108, 604799.9999999, [_meas()]).serialize()
                     + rawx(2109, 0.5, [_meas()], leap=17).serialize())
    u = read_ubx(path)
    np.testing.assert_array_equal(u.week, [2108, 2108, 2109])
    np.testing.assert_array_equal(u.tow, [270147.0000039, 604799.9999999, 0.5])
    np.testing.assert_array_equal(u.leap_seconds, [np.nan, 18.0, 17.0])
    bad = tmp_path / "w.ubx"
    bad.write_bytes(rawx(2108, 604800.5, [_meas()]).serialize())
    with pytest.raises(DataError, match=r"byte 0 \(message 1, RXM-RAWX\): rcvTow 604800.5 is not a time of week"):
        read_ubx(bad)


def test_trkstat_invalid_pseudoranges_dropped_and_counted(tmp_path):
    epochs = [(200.0 + i, [_meas(sv=3), _meas(sv=7, prValid=0), _meas(sv=9, prValid=0),
                           _meas(sv=9, sig=3, pr=2.3e7), _meas(sv=12, sig=3, pr=2.4e7),
                           _meas(sv=130, gnss=1), _meas(sv=1, gnss=2, sig=2)]) for i in range(3)]
    path = _write(tmp_path, epochs)
    u = read_ubx(path, systems="GE")
    np.testing.assert_array_equal(u.prn, [3, 3, 3])
    assert u.rejected == {"G C1C pseudorange not valid (trkStat)": 6, "no C1C pseudorange": 3,
                          "system not read: SBAS": 3, "unknown signal: E sigId 2": 3, "no E C1C/C1X pseudorange": 3}
    # with L2 CL as the second choice, G09 takes it (its L1 is flagged), G07 stays out
    u = read_ubx(path, signals={"G": ["C1C", "C2L"]})
    np.testing.assert_array_equal(u.prn, [3, 9, 12] * 3)
    np.testing.assert_array_equal(u.signal, ["C1C", "C2L", "C2L"] * 3)
    np.testing.assert_array_equal(u.pseudorange, [2.2e7, 2.3e7, 2.4e7] * 3)
    assert u.rejected["G C1C/C2L pseudorange not valid (trkStat)"] == 3
    # every satellite flagged: an error naming the file and the counts
    bad = _write(tmp_path, [(1.0, [_meas(prValid=0)])], "bad.ubx")
    with pytest.raises(DataError, match="no GPS pseudorange .*not valid") as e:
        read_ubx(bad)
    assert e.value.file == str(bad)


def test_glonass_channels_and_slots(tmp_path):
    path = _write(tmp_path, [(1.0, [_meas(sv=4, gnss=6, freqId=13), _meas(sv=255, gnss=6, freqId=7)]),
                             (2.0, [_meas(sv=4, gnss=6, freqId=13)])])
    u = read_ubx(path, systems="R")
    assert u.glonass_channels == {4: 6} and u.rejected == {"R slot unknown": 1}
    path = _write(tmp_path, [(1.0, [_meas(sv=4, gnss=6, freqId=13)]), (2.0, [_meas(sv=4, gnss=6, freqId=12)])], "x.ubx")
    with pytest.raises(DataError, match=r"byte \d+ \(message 2, RXM-RAWX\): GLONASS slot 4: frequency channel"):
        read_ubx(path, systems="R")


def test_truncated_message_at_the_end_is_skipped_counted_and_warned(tmp_path):
    whole = _write(tmp_path, [(1.0, [_meas()]), (2.0, [_meas()])]).read_bytes()
    last = len(rawx(2108, 2.0, [_meas()]).serialize())
    for cut in (1, 2, 7, last - 1):     # inside the header, after it, inside the payload, the checksum
        path = tmp_path / f"cut{cut}.ubx"
        path.write_bytes(whole[:len(whole) - last + cut])
        with pytest.warns(DataWarning, match=rf"cut{cut}.ubx: byte {len(whole) - last}: the file ends inside"):
            u = read_ubx(path)
        assert len(u) == 1 and u.event_records == {"truncated message at end": 1}


def test_no_rawx_message(tmp_path):
    path = tmp_path / "pvt.ubx"
    path.write_bytes(nav_pvt(1000).serialize() * 3 + JUNK)
    with pytest.raises(DataError, match=r"no UBX-RXM-RAWX message .* 3 messages \(NAV-PVT: 3, bytes skipped: 8\)") as e:
        read_ubx(path)
    assert e.value.file == str(path)
    empty = tmp_path / "empty.ubx"
    empty.write_bytes(b"")
    with pytest.raises(DataError, match="no UBX-RXM-RAWX message"):
        read_ubx(empty)
    with pytest.raises(DataError, match="no such file"):
        read_ubx(tmp_path / "absent.ubx")


def test_checksum_error_names_the_byte(tmp_path):
    one = rawx(2108, 1.0, [_meas()]).serialize()
    two = bytearray(one + nav_pvt(5).serialize() + rawx(2108, 2.0, [_meas(pr=2.3e7)]).serialize())
    at = 2 * 0 + len(one) + len(nav_pvt(5).serialize())    # the third message
    two[at + 20] ^= 0x40                                     # a byte of its pseudorange
    path = tmp_path / "ck.ubx"
    path.write_bytes(bytes(two))
    with pytest.raises(DataError, match=rf"byte {at} \(message 3, UBX RXM-RAWX, \d+ bytes\): checksum .* is wrong") as e:
        read_ubx(path)
    assert e.value.file == str(path)


def test_damaged_payloads(tmp_path):
    from pyubx2.ubxhelpers import calc_checksum

    def frame(payload):
        body = b"\x02\x15" + len(payload).to_bytes(2, "little") + payload
        return b"\xb5\x62" + body + calc_checksum(body)

    good = rawx(2108, 1.0, [_meas()]).serialize()
    short = frame(good[6:-2] + b"\x00" * 5)        # a valid checksum, 5 bytes too many for numMeas 1
    path = tmp_path / "len.ubx"
    path.write_bytes(good[:0] + short)
    for decode in ("numpy", "pyubx2"):
        with pytest.raises(DataError, match=r"byte 0 \(message 1, RXM-RAWX\).*not 16 \+ 32 \* numMeas"):
            read_ubx(path, decode=decode)
    # epoch times that do not increase; a satellite twice; a GPS svId out of range
    for epochs, message in ([(2.0, [_meas()]), (1.0, [_meas()])], r"message 2, RXM-RAWX\): epoch time"), \
            ([(1.0, [_meas(), _meas()])], "G05 sigId 0 is listed twice"), \
            ([(1.0, [_meas(sv=40)])], "GPS svId 40 is not a satellite number"):
        with pytest.raises(DataError, match=message):
            read_ubx(_write(tmp_path, epochs, "d.ubx"))


def test_arguments_and_registry(tmp_path):
    path = _write(tmp_path, [(1.0, [_meas()])])
    with pytest.raises(ArgumentError, match="RINEX 3 codes"):
        read_ubx(path, signals={"G": "C1"})
    with pytest.raises(ArgumentError, match="unknown system letter"):
        read_ubx(path, systems="GX")
    with pytest.raises(ArgumentError):
        read_ubx(path, decode="fast")
    from mixnav.io.readers import ReadOptions, formats, get_reader
    assert "ubx" in formats("raw-gnss")
    out = get_reader("raw-gnss", "ubx")(path, ReadOptions())
    assert out.prn.tolist() == [5]


def test_dataset_keys(tmp_path):
    """format = "ubx" in a gnss-raw dataset and an ins-gnss [raw_gnss] table, with systems and signals."""
    from mixnav.config.dataset_schema import InsRawGnss, RawGnss
    c = RawGnss(format="ubx", file="a.ubx", navigation="n.rnx", systems=["G", "E"], signals={"E": "C1B"})
    assert c.systems == ["G", "E"] and c.signals == {"E": ["C1B"]}
    assert InsRawGnss(format="ubx", file=["a.ubx", "b.ubx"], navigation="n.rnx").files("file") == ["a.ubx", "b.ubx"]
    from .test_process_raw import SHIPPED, _cfg
    from mixnav.config.loader import load_dataset
    text = SHIPPED.replace('format = "android-gnsslogger"', 'format = "ubx"\nsystems = ["G"]')
    ds, _, _ = load_dataset(_cfg(tmp_path, text))
    assert ds.raw_gnss.format == "ubx"
    with pytest.raises(ConfigError):
        load_dataset(_cfg(tmp_path, SHIPPED.replace('format = "android-gnsslogger"', 'format = "ubx-raw"')))
    with pytest.raises(ConfigError, match="RINEX 3 codes") as e:
        load_dataset(_cfg(tmp_path, SHIPPED.replace('format = "android-gnsslogger"',
                                                    'format = "ubx"\nsignals = { G = "C1" }')))
    assert e.value.key.startswith("raw_gnss")


def test_spp_of_the_ubx_log_equals_the_rinex_files(tmp_path, urbannav):
    """GPS positioning from the u-blox log is the RINEX path's, epoch for epoch."""
    from mixnav.gnss.ephemeris import BroadcastEphemeris
    from mixnav.gnss.spp import SppOptions, solve_epochs
    l1, l2, channels, log = urbannav
    path = tmp_path / "tst.ubx"
    path.write_bytes(log)
    eph = BroadcastEphemeris.from_rinex(data_file(*OBS).with_name("hksc155c.20n"))
    g = first_epochs(__import__("mixnav.io.rinex_obs", fromlist=["x"]).read_rinex_obs(data_file(*OBS)), 30)
    u = read_ubx(path)
    a = solve_epochs(eph, g.week, g.tow, g.epoch, g.prn, g.pseudorange, SppOptions())
    b = solve_epochs(eph, u.week, u.tow, u.epoch, u.prn, u.pseudorange, SppOptions())
    assert a.ok.sum() == 30
    np.testing.assert_array_equal(a.pos_ecef, b.pos_ecef)


def test_fails_without_the_fix(tmp_path, urbannav):
    """The round-trip comparison notices a pseudorange off by one float32 step (what
    an R4 field would do): the test can fail."""
    l1, l2, channels, log = urbannav
    path = tmp_path / "tst.ubx"
    path.write_bytes(log)
    u = read_ubx(path, systems="GRECJ")
    worse = dataclasses.replace(u, pseudorange=u.pseudorange.astype(np.float32).astype(float))
    with pytest.raises(AssertionError):
        same_as_rinex(worse, l1, channels)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_ubx(path)        # a whole log: no warning


def test_gnss_raw_dataset_with_a_ubx_log(tmp_path, urbannav):
    """A gnss-raw dataset naming the u-blox log (format = "ubx") solves its 30 epochs as the
    same dataset on the RINEX file does (GPS alone, as the RINEX path)."""
    import shutil
    from mixnav.config.loader import load_dataset
    from mixnav.experiment.spp_process import process_raw, solution_table
    from .test_process_raw import SHIPPED, _cfg
    *_, log = urbannav
    (tmp_path / "tst.ubx").write_bytes(log)
    obs = data_file(*OBS)
    shutil.copy(obs.with_name("hksc155c.20n"), tmp_path)
    text = SHIPPED.replace('file = "pseudoranges_log_2016_06_30_21_26_07.txt"', 'file = "tst.ubx"').replace(
        'navigation = "hour1820.16n"', 'navigation = "hksc155c.20n"')
    tables = {}
    for fmt, name in (("ubx", "tst.ubx"), ("rinex-obs", str(obs))):
        t = text.replace('format = "android-gnsslogger"', f'format = "{fmt}"').replace('"tst.ubx"', f'"{name}"')
        ds, src, _ = load_dataset(_cfg(tmp_path, t, f"{fmt}.toml"))
        assert ds.raw_gnss.format == fmt
        tables[fmt] = solution_table(process_raw(ds, src, tmp_path))
    u, r = tables["ubx"], tables["rinex-obs"].iloc[:30].reset_index(drop=True)
    assert len(u) == 30 and (u.status == "ok").all()
    import pandas as pd
    pd.testing.assert_frame_equal(u, r)


def test_ins_raw_reads_ubx_logs_in_time_order(tmp_path, urbannav):
    """The ins-gnss [raw_gnss] path reads a list of u-blox logs as one record (leap seconds too)."""
    from mixnav.experiment.rinex_ins import read_observations
    from mixnav.io.readers import ReadOptions, get_reader
    l1, l2, channels, _ = urbannav
    epochs = rows_of([l1, l2], channels)
    paths = [tmp_path / "a.ubx", tmp_path / "b.ubx"]
    paths[0].write_bytes(log_bytes(epochs[:12]))
    paths[1].write_bytes(log_bytes(epochs[12:]))
    (tmp_path / "all.ubx").write_bytes(log_bytes(epochs))
    opts = ReadOptions(dataclasses.make_dataclass("T", [("systems", list, dataclasses.field(default_factory=lambda: list("GRECJ")))])())
    both = read_observations(paths, get_reader("raw-gnss", "ubx"), opts)
    whole = read_ubx(tmp_path / "all.ubx", systems="GRECJ")
    for f in FIELDS[:-1] + ("week", "tow", "leap_seconds"):
        np.testing.assert_array_equal(getattr(both, f), getattr(whole, f), err_msg=f)
    assert both.glonass_channels == whole.glonass_channels
    with pytest.raises(DataError, match="time order"):
        read_observations(paths[::-1], get_reader("raw-gnss", "ubx"), opts)
