"""Every system's observations from RINEX (issue 36): GPS, GLONASS, Galileo, BeiDou and
QZSS pseudorange, carrier, Doppler, C/N0 and loss-of-lock indicators read by io.rinex_obs's
own numpy reader, checked against georinex's parse of the same files (RINEX 3.03 and 3.02
and RINEX 2.11 files written here with random values, and the urbannav RINEX 3.02 file),
against the values written (round trips), and bad input (unknown systems and signals,
records that do not fit the header's types, GLONASS rows without a frequency channel)."""

import warnings

import numpy as np
import pytest

from mixnav.errors import ArgumentError, ConfigError, DataError

from .conftest import data_file

GPS0 = np.datetime64("1980-01-06T00:00:00", "ns")
T0 = np.datetime64("2020-06-03T03:02:27.004", "ns")
URBANNAV = ("urbannav-tst-static", "2020_06_03_TST_03.obs")

#: observation types per system of the RINEX 3.03 files written here (S: SBAS, not read)
TYPES3 = {"G": ["C1C", "L1C", "D1C", "S1C", "C2W", "L2W", "C5Q", "L5Q", "D5Q", "S5Q", "C1W", "L1W", "D1W", "S1W"],
          "R": ["C1C", "L1C", "D1C", "S1C", "C2P"], "E": ["C1X", "L1X", "D1X", "S1X", "C7Q", "L7Q"],
          "C": ["C2I", "L2I", "D2I", "S2I", "C7I"], "J": ["C1C", "L1C", "D1C", "S1C"], "S": ["C1C", "L1C"]}
#: the same in RINEX 2.11 (one list for every system)
TYPES2 = ["C1", "P1", "L1", "D1", "S1", "C2", "P2", "L2"]
SATS = {"G": [3, 7, 12, 30], "R": [1, 5, 17], "E": [2, 11, 36], "C": [6, 19, 45], "J": [1, 3], "S": [20]}
#: the header's GLONASS channels (R17 left out: it has none)
CHANNELS = {1: 1, 5: -4, 9: 6, 2: -7, 3: 0, 4: 2, 6: -1, 7: 5, 8: 3}


def _value(rng, t):
    """A random observation of type ``t`` (m, cycles, Hz, dB-Hz) to the file's 1e-3."""
    v = {"C": rng.uniform(1.9e7, 4.0e7), "P": rng.uniform(1.9e7, 4.0e7), "L": rng.uniform(-2e8, 2.1e8),
         "D": rng.uniform(-4500, 4500), "S": rng.uniform(20, 52)}[t[0]]
    return round(v, 3)


def _draw(rng, n_epochs, types, version, sats=SATS):
    """Per epoch a list of (satellite, {type: (value or None, lli char, ssi char)}): random
    values, about 10 % blank, LLI and SSI characters random (blank or digits)."""
    out = []
    for _ in range(n_epochs):
        recs = []
        for s, prns in sats.items():
            for p in prns:
                if rng.random() < 0.1:
                    continue
                ts = types if version < 3 else types[s]
                fields = {}
                for t in ts:
                    v = None if rng.random() < 0.1 else _value(rng, t)
                    lli = str(rng.choice([" ", " ", "0", "1", "2", "5"]))
                    ssi = str(rng.choice([" ", "1", "5", "9"]))
                    fields[t] = (v, lli, ssi)
                recs.append((f"{s}{p:02d}", fields))
        order = rng.permutation(len(recs))     # any record order, as receivers write
        out.append([recs[i] for i in order])
    return out


def _cell(field):
    v, lli, ssi = field
    return (" " * 14 if v is None else f"{v:14.3f}") + lli + ssi


def _stamp(k):
    t = T0 + np.timedelta64(k * 1000 + (500 if k % 7 == 3 else 0), "ms")
    date, clock = str(t).split("T")
    y, mo, d = (int(x) for x in date.split("-"))
    hh, mm, ss = clock.split(":")
    return t, y, mo, d, int(hh), int(mm), float(ss)


def _write3(path, epochs, version="3.03", types=TYPES3, glonass=CHANNELS):
    """A RINEX 3 mixed observation file of ``epochs`` (:func:`_draw`), trailing blanks stripped."""
    _, y, mo, d, hh, mm, ss = _stamp(0)
    head = [(f"{version:>9s}{'':11s}{'OBSERVATION DATA':<20s}{'M (MIXED)':<20s}", "RINEX VERSION / TYPE"),
            ("mixnav test", "PGM / RUN BY / DATE"), ("TEST", "MARKER NAME")]
    for s, ts in types.items():
        head.append((f"{s}  {len(ts):3d}" + "".join(f" {t}" for t in ts[:13]), "SYS / # / OBS TYPES"))
        for i in range(13, len(ts), 13):
            head.append(("      " + "".join(f" {t}" for t in ts[i:i + 13]), "SYS / # / OBS TYPES"))
    head.append((f"{y:6d}{mo:6d}{d:6d}{hh:6d}{mm:6d}{ss:13.7f}     GPS", "TIME OF FIRST OBS"))
    items = list(glonass.items())
    for i in range(0, max(len(items), 1), 8):
        cnt = f"{len(items):3d} " if i == 0 else "    "
        head.append((cnt + "".join(f"R{s:02d} {k:2d} " for s, k in items[i:i + 8]), "GLONASS SLOT / FRQ #"))
    head.append(("", "END OF HEADER"))
    lines = [f"{a:<60s}{b:<20s}" for a, b in head]
    for k, recs in enumerate(epochs):
        _, y, mo, d, hh, mm, ss = _stamp(k)
        lines.append(f"> {y:04d} {mo:02d} {d:02d} {hh:02d} {mm:02d}{ss:11.7f}  0{len(recs):3d}")
        for name, fields in recs:
            lines.append((name + "".join(_cell(fields[t]) for t in types[name[0]])).rstrip())
    path.write_text("\n".join(lines) + "\n")


def _write2(path, epochs, types=TYPES2):
    """A RINEX 2.11 mixed observation file of ``epochs`` (:func:`_draw`), satellite lists over
    12 on continuation lines, 5 fields a line, trailing blanks stripped."""
    _, y, mo, d, hh, mm, ss = _stamp(0)
    tl = [f"{len(types):6d}" + "".join(f"{t:>6s}" for t in types[:9])]
    tl += [" " * 6 + "".join(f"{t:>6s}" for t in types[i:i + 9]) for i in range(9, len(types), 9)]
    head = [("     2.11           OBSERVATION DATA    M (MIXED)", "RINEX VERSION / TYPE"),
            ("mixnav test", "PGM / RUN BY / DATE"), ("TEST", "MARKER NAME"),
            *[(t, "# / TYPES OF OBSERV") for t in tl],
            (f"{y:6d}{mo:6d}{d:6d}{hh:6d}{mm:6d}{ss:13.7f}     GPS", "TIME OF FIRST OBS"), ("", "END OF HEADER")]
    lines = [f"{a:<60s}{b:<20s}" for a, b in head]
    for k, recs in enumerate(epochs):
        _, y, mo, d, hh, mm, ss = _stamp(k)
        names = [n for n, _ in recs]
        lines.append(f" {y % 100:02d} {mo:2d} {d:2d} {hh:2d} {mm:2d}{ss:11.7f}  0{len(names):3d}" + "".join(names[:12]))
        lines += [" " * 32 + "".join(names[i:i + 12]) for i in range(12, len(names), 12)]
        for _, fields in recs:
            cells = [_cell(fields[t]) for t in types]
            lines += ["".join(cells[i:i + 5]).rstrip() for i in range(0, len(cells), 5)]
    path.write_text("\n".join(lines) + "\n")


def _georinex(path, indicators=False):
    import georinex
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return georinex.load(path, fast=False, useindicators=indicators)


def _ours_every_value(path, systems="GRECJ"):
    """{(epoch time, satellite, type): value} of every observation field of the systems read,
    from the reader's own walk and field parser (every type, not only the signals chosen)."""
    from pathlib import Path

    from mixnav.io import rinex_obs as ro
    path = Path(path)
    lines = ro._text_lines(path)
    header = ro._header(lines, path)
    listing = ro._listing(lines, path, tuple(systems), header)
    values, lli = ro._fields(listing, path)
    out, flags = {}, {}
    rinex3 = listing.version >= 3
    for r in range(len(listing.rec_epoch)):
        s = str(listing.rec_system[r])
        sat = f"{s}{listing.rec_prn[r]:02d}"
        t = listing.times[listing.rec_epoch[r]]
        for j, typ in enumerate(header[3][s if rinex3 else " "]):   # the system's types
            if np.isfinite(values[r, j]):
                out[(t, sat, typ)] = float(values[r, j])
            flags[(t, sat, typ)] = int(lli[r, j])
    return out, flags


def _theirs_every_value(g, systems="GRECJ"):
    out = {}
    times = np.asarray(g.time.values).astype("datetime64[ns]")
    for typ in g.data_vars:
        if typ.endswith(("lli", "ssi")):
            continue
        v = g[typ].values
        for j, sv in enumerate(str(x) for x in g.sv.values):
            if sv[0] not in systems:
                continue
            for i in np.flatnonzero(np.isfinite(v[:, j])):
                out[(times[i], sv, typ)] = float(v[i, j])
    return out


def _same_times(ours, theirs, tol=2000):
    """Our epoch times (ns, from the records) -> georinex's (truncated to us, its float
    truncation sometimes a unit more: .504 -> .503999; RINEX 2 to ms when its file-size
    guess fails), epoch by epoch, at most ``tol`` ns earlier: the key map."""
    ours = np.array(sorted(ours), dtype="datetime64[ns]")
    theirs = np.asarray(theirs).astype("datetime64[ns]")
    assert len(ours) == len(theirs)
    late = (ours - theirs).astype(np.int64)
    assert late.min() >= 0 and late.max() < tol, late.max()
    return dict(zip(ours, theirs))


def _compare_every_value(path, g, systems="GRECJ", tol=2000):
    """Every observation value of every system, type and epoch: ours == georinex's, exactly."""
    ours, _ = _ours_every_value(path, systems)
    theirs = _theirs_every_value(g, systems)
    tmap = _same_times({k[0] for k in ours}, g.time.values, tol)
    ours = {(tmap[t], sv, typ): v for (t, sv, typ), v in ours.items()}
    assert len(ours) == len(theirs) > 0
    assert ours.keys() == theirs.keys()
    diff = [k for k in ours if ours[k] != theirs[k]]
    assert not diff, [(k, ours[k], theirs[k]) for k in diff[:5]]
    return len(ours)


def _compare_signals(path, g, types, rinex3):
    """Through the public reader: for every system and every pseudorange code of its header
    types, read that signal alone and compare pseudorange, carrier, Doppler and C/N0 (and
    the carrier's loss-of-lock indicator where georinex gives it: L1*, L2*) with georinex at
    every epoch and satellite."""
    from mixnav.gnss.signals import companions
    from mixnav.io.rinex_obs import read_rinex_obs
    gt = np.asarray(g.time.values).astype("datetime64[ns]")
    svs = [str(x) for x in g.sv.values]
    checked = 0
    for s in "GRECJ":
        listed = types[s] if rinex3 else types
        for code in [c for c in listed if c[0] in "CP"]:
            r = read_rinex_obs(path, systems=[s], signals={s: code})
            assert (r.system == s).all() and (r.signal == code).all() and r.code == code
            t = GPS0 + (r.week.astype(np.int64) * 604800 * 10**9 + np.round(r.tow * 1e9).astype(np.int64)) \
                .astype("timedelta64[ns]")
            i = np.searchsorted(gt, t[r.epoch], side="right") - 1     # georinex's time: at most 2 us before ours
            late = (t[r.epoch] - gt[i]).astype(np.int64)
            assert late.min() >= 0 and late.max() < 2000
            j = np.array([svs.index(x) for x in r.satellite_ids()])
            np.testing.assert_array_equal(r.pseudorange, g[code].values[i, j])
            # every value of that signal georinex has is read
            assert np.isfinite(g[code].values[:, [k for k, x in enumerate(svs) if x[0] == s]]).sum() == len(r.prn)
            for name, comp in zip(("carrier", "doppler", "cn0"), companions(code)):
                got = getattr(r, name)
                if comp in listed:
                    np.testing.assert_array_equal(got, g[comp].values[i, j], err_msg=f"{s} {code} {name}")
                else:
                    assert got is None or np.isnan(got).all()
            lcode = companions(code)[0]
            if lcode + "lli" in g.data_vars:
                np.testing.assert_array_equal(r.lli[:, 1], np.nan_to_num(g[lcode + "lli"].values[i, j]).astype(int))
            checked += len(r.prn)
    return checked


@pytest.mark.parametrize("version", ["3.03", "3.02"])
def test_rinex3_every_system_and_signal_equals_georinex(tmp_path, version):
    """A RINEX 3 mixed file (5 systems and SBAS, up to 14 types a system: continuation lines,
    records in random order, 10 % blank values, random LLI / signal strength, lines with
    trailing blanks stripped): every value of every type equals georinex's parse, and
    through the public reader every signal's pseudorange, carrier, Doppler, C/N0 and the
    carrier's LLI. RINEX 3.02 names BeiDou B1 C1I (the default finds it after C2I)."""
    rng = np.random.default_rng(36)
    types = dict(TYPES3)
    if version == "3.02":
        types["C"] = ["C1I", "L1I", "D1I", "S1I", "C7I"]
    epochs = _draw(rng, 25, types, 3)
    path = tmp_path / "multi.rnx"
    _write3(path, epochs, version, types)
    g = _georinex(path, indicators=True)
    n = _compare_every_value(path, g)
    assert n > 2000
    assert _compare_signals(path, g, types, True) > 500
    # and the values written (round trip), LLI of every field included
    ours, flags = _ours_every_value(path)
    for k, recs in enumerate(epochs):
        t = _stamp(k)[0]
        for name, fields in recs:
            if name[0] == "S":
                continue
            for typ, (v, lli, _) in fields.items():
                assert ours.get((t, name, typ)) == v
                assert flags[(t, name, typ)] == (0 if lli == " " else int(lli))


def test_rinex2_every_system_and_signal_equals_georinex(tmp_path):
    """The same for a RINEX 2.11 mixed file (8 types on two lines a record, satellite lists
    over 12 on continuation lines; satellite numbers up to 36, as georinex's RINEX 2 reader
    wants): every value georinex reads equals ours, and the public reader's C1, P1, C2 and
    P2 of every system, and every value and LLI, are those written."""
    rng = np.random.default_rng(211)
    epochs = _draw(rng, 20, TYPES2, 2, {**SATS, "C": [6, 19, 35]})   # georinex's RINEX 2: numbers up to 36
    path = tmp_path / "multi.20o"
    _write2(path, epochs)
    g = _georinex(path)
    known = "".join(sorted({str(x)[0] for x in g.sv.values} & set("GRECJ")))
    assert set(known) >= set("GRE")
    assert _compare_every_value(path, g, known, tol=1_100_000) > 2000
    ours, flags = _ours_every_value(path)
    for k, recs in enumerate(epochs):
        t = _stamp(k)[0]
        for name, fields in recs:
            if name[0] == "S":
                continue
            for typ, (v, lli, _) in fields.items():
                assert ours.get((t, name, typ)) == v
                assert flags[(t, name, typ)] == (0 if lli == " " else int(lli))
    from mixnav.io.rinex_obs import read_rinex_obs
    for s in known:
        for code in ("C1", "P1", "C2", "P2"):
            r = read_rinex_obs(path, systems=[s], signals={s: code})
            written = {(int(_stamp(k)[0].astype("datetime64[us]").astype(np.int64)), int(n[1:])):
                       (f[code][0], f["L" + code[1]][0], f["D" + code[1]][0] if "D" + code[1] in f else None)
                       for k, recs in enumerate(epochs) for n, f in recs if n[0] == s and f[code][0] is not None}
            t = (GPS0 + (r.week.astype(np.int64) * 604800 * 10**9 + np.round(r.tow * 1e9).astype(np.int64))
                 .astype("timedelta64[ns]")).astype("datetime64[us]").astype(np.int64)
            got = {(int(t[e]), int(p)): (v, c, d) for e, p, v, c, d in zip(r.epoch, r.prn, r.pseudorange, r.carrier,
                                                                           r.doppler if r.doppler is not None
                                                                           else [None] * len(r.prn))}
            assert got.keys() == written.keys()
            for key, (v, c, d) in written.items():
                gv, gc, gd = got[key]
                assert gv == v and (gc == c or (c is None and np.isnan(gc)))
                assert (d is None and (gd is None or np.isnan(gd))) or gd == d


def _first_epochs(path, n, out):
    """The header and the first ``n`` epoch records of a RINEX 3 file, written to ``out``."""
    lines = path.read_text().splitlines()
    at = [i for i, ln in enumerate(lines) if ln.startswith(">")]
    out.write_text("\n".join(lines[:at[n]]) + "\n")
    return out


def _urbannav_check(path, g):
    from mixnav.io.rinex_obs import _header, _text_lines
    types = _header(_text_lines(path), path)[3]
    assert _compare_every_value(path, g) > 1000
    assert _compare_signals(path, g, types, True) > 100


def test_urbannav_first_epochs_equal_georinex(tmp_path):
    """The urbannav RINEX 3.02 file (u-blox via RTKCONV: satellite numbers with a blank,
    ``G 7``; BeiDou as C1I; values padded with blanks): its first 60 epochs, every value of
    every system and type and every signal through the public reader, equal georinex's.
    (The whole file: the slow test below.)"""
    path = _first_epochs(data_file(*URBANNAV), 60, tmp_path / "tst60.obs")
    _urbannav_check(path, _georinex(path, indicators=True))


@pytest.mark.slow
def test_urbannav_whole_file_equals_georinex():
    """As above, every one of the file's 986 epochs (georinex takes about a minute)."""
    path = data_file(*URBANNAV)
    _urbannav_check(path, _georinex(path, indicators=True))


def test_urbannav_systems_defaults_and_order():
    """The urbannav file read with every system: GPS rows equal the GPS-only read (the
    default), other systems' defaults find their signals (C1C; BeiDou's C1I after C2I),
    rows ordered by epoch, system (G R E C J) and satellite, each system's records
    counted, the header's empty GLONASS channel list gives none (check names the line)."""
    from mixnav.io.rinex_obs import read_rinex_obs
    path = data_file(*URBANNAV)
    gps = read_rinex_obs(path)
    every = read_rinex_obs(path, systems="GRECJ")
    assert set(gps.rejected) == {"not GPS: C", "not GPS: E", "not GPS: J", "not GPS: R", "no C1C pseudorange"}
    assert every.code == "C1C/C1I" and set(every.signal[every.system == "C"]) == {"C1I"}
    g = every.system == "G"
    np.testing.assert_array_equal(every.pseudorange[g], gps.pseudorange)
    np.testing.assert_array_equal(every.prn[g], gps.prn)
    np.testing.assert_array_equal(every.tow, gps.tow)
    rank = np.array(["GRECJ".index(s) for s in every.system])
    key = (every.epoch * 10 + rank) * 100 + every.prn
    assert (np.diff(key) > 0).all()
    records = {s: int((every.system == s).sum()) for s in "GRECJ"}
    text = path.read_text().splitlines()
    end = next(i for i, ln in enumerate(text) if "END OF HEADER" in ln)
    for s in "GRECJ":   # every record is a row or is counted
        n_file = sum(1 for ln in text[end + 1:] if ln[:1] == s)
        lost = every.rejected.get("no C1C pseudorange", 0) if s == "G" else \
            sum(v for k, v in every.rejected.items() if k.startswith(f"no {s} "))
        assert records[s] + lost == n_file, s
    assert every.glonass_channels == {}
    with pytest.raises(DataError, match="GLONASS slots R") as e:
        every.check_glonass_channels()
    first = int(np.flatnonzero(every.system == "R")[0])
    assert e.value.line == every.line[first] and text[e.value.line - 1].startswith("R")
    assert e.value.file == str(path)
    gps.check_glonass_channels()     # no GLONASS row: nothing needed


def test_glonass_channels_from_header_and_attached(tmp_path):
    """The header's GLONASS SLOT / FRQ # (9 slots: a continuation line) gives each GLONASS
    row its channel; R17, absent there, has none until attached (a conflicting number
    for a slot the header gives is a DataError); a channel outside -7..6 in the header is
    a DataError naming its line."""
    from mixnav.data import NO_CHANNEL
    from mixnav.io.rinex_obs import read_rinex_obs
    rng = np.random.default_rng(5)
    path = tmp_path / "glo.rnx"
    _write3(path, _draw(rng, 8, TYPES3, 3))
    r = read_rinex_obs(path, systems=["G", "R"])
    assert r.glonass_channels == dict(sorted(CHANNELS.items()))
    ch = r.glonass_channel()
    glo = r.system == "R"
    assert (ch[~glo] == NO_CHANNEL).all()
    for slot in (1, 5):
        assert (ch[glo & (r.prn == slot)] == CHANNELS[slot]).all()
    assert (ch[glo & (r.prn == 17)] == NO_CHANNEL).all()
    with pytest.raises(DataError, match="R17") as e:
        r.check_glonass_channels()
    assert e.value.line == int(r.line[np.flatnonzero(glo & (r.prn == 17))[0]])
    assert path.read_text().splitlines()[e.value.line - 1].startswith("R17")
    r2 = r.with_glonass_channels({17: 4, 1: 1})
    r2.check_glonass_channels()
    assert (r2.glonass_channel()[glo & (r.prn == 17)] == 4).all() and r.glonass_channels.get(17) is None
    with pytest.raises(DataError, match="slot 5: frequency channel 2 given, but the observation header gives -4"):
        r.with_glonass_channels({5: 2})
    lines = path.read_text().splitlines()
    j = next(i for i, ln in enumerate(lines) if "GLONASS SLOT" in ln)
    lines[j] = lines[j][:4] + "R01  9" + lines[j][10:]
    (tmp_path / "bad.rnx").write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match="channel 9 of R01 is outside") as e:
        read_rinex_obs(tmp_path / "bad.rnx", systems="GR")
    assert e.value.line == j + 1


def test_signal_preference_falls_back_per_record(tmp_path):
    """Galileo's default C1C then C1X: a file listing both takes C1C where a record has it
    and C1X where only that is written, with each row's carrier / Doppler / C/N0 of the
    same signal; ``signals`` reverses the order; RINEX 3 codes are refused for a RINEX 2
    file (naming line 1), RINEX 2 codes read it."""
    from mixnav.io.rinex_obs import read_rinex_obs
    types = {"E": ["C1C", "L1C", "C1X", "L1X", "D1X"]}
    epochs = []
    for k in range(4):
        f = {"C1C": (2.1e7 + k, " ", " "), "L1C": (1.1e8 + k, "1", " "), "C1X": (2.2e7 + k, " ", " "),
             "L1X": (1.2e8 + k, " ", " "), "D1X": (100.0 + k, " ", " ")}
        if k % 2:
            f["C1C"] = (None, " ", " ")
        epochs.append([("E11", f)])
    path = tmp_path / "e.rnx"
    _write3(path, epochs, types=types, glonass={})
    r = read_rinex_obs(path, systems="E")
    assert r.signal.tolist() == ["C1C", "C1X", "C1C", "C1X"] and r.code == "C1C/C1X"
    np.testing.assert_array_equal(r.pseudorange, [2.1e7, 2.2e7 + 1, 2.1e7 + 2, 2.2e7 + 3])
    np.testing.assert_array_equal(r.carrier, [1.1e8, 1.2e8 + 1, 1.1e8 + 2, 1.2e8 + 3])
    np.testing.assert_array_equal(r.doppler, [np.nan, 101.0, np.nan, 103.0])
    assert r.lli[:, 1].tolist() == [1, 0, 1, 0] and r.cn0 is None
    r = read_rinex_obs(path, systems="E", signals={"E": ["C1X", "C1C"]})
    assert (r.signal == "C1X").all()
    rng = np.random.default_rng(2)
    p2 = tmp_path / "e.20o"
    _write2(p2, _draw(rng, 3, TYPES2, 2))
    with pytest.raises(DataError, match=r"signals.E: C1X: no RINEX 2 code") as e:
        read_rinex_obs(p2, systems="E", signals={"E": "C1X"})
    assert e.value.line == 1
    assert (read_rinex_obs(p2, systems="E", signals={"E": ["C1X", "P1"]}).signal == "P1").all()


def test_unknown_systems_and_signals_are_named(tmp_path):
    """An unknown system letter or signal code: ArgumentError naming the argument (the
    reader) and ConfigError naming the key (the dataset file); a code the header does not
    list for the system: DataError naming the system's header line; the phone-log format
    takes neither key; a positioning dataset asking for more than GPS is refused by key."""
    from mixnav.config import load_dataset
    from mixnav.io.rinex_obs import read_rinex_obs
    rng = np.random.default_rng(3)
    path = tmp_path / "m.rnx"
    _write3(path, _draw(rng, 3, TYPES3, 3))
    with pytest.raises(ArgumentError, match="unknown system letter 'X'") as e:
        read_rinex_obs(path, systems=["G", "X"])
    assert e.value.argument == "systems"
    with pytest.raises(ArgumentError, match="'S1C' is not a code-pseudorange") as e:
        read_rinex_obs(path, systems="GE", signals={"E": ["C1X", "S1C"]})
    assert e.value.argument == "signals.E"
    with pytest.raises(ArgumentError, match="'C1C' is not a RINEX 3 pseudorange code of BeiDou") as e:
        read_rinex_obs(path, systems="C", signals={"C": "C1C"})
    assert e.value.argument == "signals.C"
    with pytest.raises(DataError, match=r"no Galileo pseudorange of the signals asked for: .* lists C1X L1X") as e:
        read_rinex_obs(path, systems="GE", signals={"E": "C5Q"})
    lines = path.read_text().splitlines()
    assert lines[e.value.line - 1].startswith("E ") and "SYS / # / OBS TYPES" in lines[e.value.line - 1]
    _write3(tmp_path / "g.rnx", _draw(rng, 3, {"G": TYPES3["G"]}, 3, {"G": SATS["G"]}), types={"G": TYPES3["G"]}, glonass={})
    with pytest.raises(DataError, match=r"no GLONASS observation types: .* list the systems G \(R with C1C is needed\)"):
        read_rinex_obs(tmp_path / "g.rnx", systems="GR")
    # the dataset file: keys named
    from .test_process_raw import SHIPPED, _cfg
    rinex = SHIPPED.replace('format = "android-gnsslogger"', 'format = "rinex-obs"')
    for text, key, message in [
        (rinex.replace('format = "rinex-obs"', 'format = "rinex-obs"\nsystems = ["G", "X"]'), "raw_gnss.systems",
         "unknown system letter 'X'"),
        (rinex.replace('format = "rinex-obs"', 'format = "rinex-obs"\nsignals = { E = ["C1C", "L1C"] }'),
         "raw_gnss.signals", "E: 'L1C' is not a code-pseudorange"),
        (rinex.replace('format = "rinex-obs"', 'format = "rinex-obs"\nsignals = { Q = "C1C" }'),
         "raw_gnss.signals", "unknown system letter 'Q'"),
        (SHIPPED.replace('format = "android-gnsslogger"', 'format = "android-gnsslogger"\nsystems = ["G", "E"]'),
         "raw_gnss", 'only format = "rinex-obs"'),
    ]:
        with pytest.raises(ConfigError, match=message) as e:
            load_dataset(_cfg(tmp_path, text))
        assert e.value.key == key
    ds, src, _ = load_dataset(_cfg(tmp_path, rinex.replace('format = "rinex-obs"',
                                                           'format = "rinex-obs"\nsystems = ["G", "E"]')))
    assert ds.raw_gnss.systems == ["G", "E"]
    from mixnav.experiment.spp_process import solve_raw
    # several systems are solved now (tests/test_spp_multi.py); a signal other than the
    # system's first-frequency one is refused, naming the key, before any file is read
    from mixnav.experiment.spp_process import read_raw
    ds2, src2, _ = load_dataset(_cfg(tmp_path, rinex.replace(
        'format = "rinex-obs"', 'format = "rinex-obs"\nsystems = ["G", "E"]\nsignals = { E = "C5Q" }')))
    with pytest.raises(ConfigError, match="E: C5Q is not the system's first-frequency") as e:
        read_raw(ds2, src2, tmp_path)
    assert e.value.key == "raw_gnss.signals.E"
    # observations of other systems handed over directly with GPS records alone (library use)
    with pytest.raises(ArgumentError, match="observations of systems E, R with GPS navigation records alone") as e:
        solve_raw(ds, src, tmp_path, read_rinex_obs(path, systems="GRE"), None)
    assert e.value.argument == "obs"


def _record(letter):
    """Finds a RINEX 3 satellite record line of the system ``letter`` (not a header line)."""
    return lambda ln: ln[:1] == letter and ln[1:3].isdigit() and "OBS TYPES" not in ln


def _damage(path, find, edit):
    lines = path.read_text().splitlines()
    j = next(i for i, ln in enumerate(lines) if find(ln))
    lines[j] = edit(lines[j])
    path.write_text("\n".join(lines) + "\n")
    return j + 1


@pytest.mark.parametrize("version, find, edit, systems, message", [
    # a record with values past the header's types (its system's count)
    (3, _record("J"), lambda ln: ln.ljust(3 + 4 * 16) + "  12345678.901", "GJ",
     "values beyond the header's 4 observation types"),
    # a RINEX 2 record line longer than 5 fields
    (2, lambda ln: len(ln) > 60 and "." in ln[:16] and "RINEX" not in ln, lambda ln: ln.ljust(80) + "   1.000", "GRECJ",
     "a line longer than 5 observation fields"),
    # not a number; a loss-of-lock indicator that is no digit
    (3, _record("E"), lambda ln: ln[:3] + "  2x123456.789" + ln[17:], "E", "'2x123456.789' is not a number"),
    (3, _record("G"), lambda ln: ln[:3] + f"{2.1e7:14.3f}" + "x" + ln[18:], "G",
     "loss-of-lock indicator 'x' is not a digit"),
    (3, _record("C"), lambda ln: ln[:3] + "           nan" + ln[17:], "C", "'nan' is not a number"),
    (3, _record("R"), lambda ln: "RAB" + ln[3:], "R", "'RAB' is not a satellite number"),
])
def test_records_that_do_not_fit_name_file_and_line(tmp_path, version, find, edit, systems, message):
    """Records that do not fit the header's observation types (values past them, a RINEX 2
    line of more than 5 fields), a field that is no number (also 'nan'), a loss-of-lock
    indicator that is no digit, a satellite number that is none: DataError naming the file
    and line."""
    from mixnav.io.rinex_obs import read_rinex_obs
    rng = np.random.default_rng(7)
    path = tmp_path / f"d.{version}o"
    if version == 3:
        _write3(path, _draw(rng, 4, TYPES3, 3))
    else:   # every record one of a system read
        _write2(path, _draw(rng, 4, TYPES2, 2, {s: p for s, p in SATS.items() if s != "S"}))
    line = _damage(path, find, edit)
    with pytest.raises(DataError, match=message) as e:
        read_rinex_obs(path, systems=systems)
    assert e.value.file == str(path) and e.value.line == line, str(e.value)


def test_numbers_not_written_f14_3_and_a_satellite_listed_twice(tmp_path):
    """A value written otherwise than F14.3 (``2.012345e+07``, ``12.5``) is read as its text's
    float, as georinex reads it; a satellite twice in one epoch is a DataError naming the
    second record's line."""
    from mixnav.io.rinex_obs import read_rinex_obs
    f = {"C1C": (2.1e7, " ", " "), "L1C": (1.1e8, " ", " ")}
    epochs = [[("G05", dict(f)), ("G06", dict(f))] for _ in range(2)]
    path = tmp_path / "n.rnx"
    _write3(path, epochs, types={"G": ["C1C", "L1C"]}, glonass={})
    lines = path.read_text().splitlines()
    g5 = [i for i, ln in enumerate(lines) if ln.startswith("G05")]
    lines[g5[0]] = "G05  2.012345e+07" + lines[g5[0]][17:]
    lines[g5[1]] = "G05          12.5" + lines[g5[1]][17:]
    path.write_text("\n".join(lines) + "\n")
    r = read_rinex_obs(path)
    assert r.pseudorange[r.prn == 5].tolist() == [2.012345e7, 12.5]
    g = _georinex(path)
    np.testing.assert_array_equal(g["C1C"].sel(sv="G05").values, [2.012345e7, 12.5])
    lines[g5[1] + 1] = "G05" + lines[g5[1] + 1][3:]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match="satellite G05 is listed twice") as e:
        read_rinex_obs(path)
    assert e.value.line == g5[1] + 2


def test_files_merged_keep_every_field(tmp_path):
    """Observation files read one after the other (rinex_ins.read_observations, the
    ins-gnss route) with the dataset's systems: one record equal to the single file's read,
    every new field (system, signal, carrier, LLI, C/N0, GLONASS channels) carried."""
    from types import SimpleNamespace

    from mixnav.experiment.rinex_ins import read_observations
    from mixnav.io.readers import ReadOptions
    from mixnav.io.rinex_obs import read_rinex_obs
    rng = np.random.default_rng(11)
    epochs = _draw(rng, 12, TYPES3, 3)
    _write3(tmp_path / "all.rnx", epochs)
    lines = (tmp_path / "all.rnx").read_text().splitlines()
    at = [i for i, ln in enumerate(lines) if ln.startswith(">")]
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    (tmp_path / "a.rnx").write_text("\n".join(lines[:at[5]]) + "\n")
    (tmp_path / "b.rnx").write_text("\n".join(lines[:end + 1] + lines[at[5]:]) + "\n")
    whole = read_rinex_obs(tmp_path / "all.rnx", systems="GRECJ")
    table = SimpleNamespace(systems=list("GRECJ"), signals={})
    merged = read_observations([tmp_path / "a.rnx", tmp_path / "b.rnx"], options=ReadOptions(table, tmp_path))
    for name in ("week", "tow", "epoch", "prn", "system", "signal", "pseudorange", "carrier", "doppler", "cn0", "lli"):
        np.testing.assert_array_equal(getattr(merged, name), getattr(whole, name), err_msg=name)
    assert merged.glonass_channels == whole.glonass_channels == dict(sorted(CHANNELS.items()))
    assert merged.rejected == whole.rejected and merged.code == whole.code


def test_raw_pseudoranges_checks_the_new_fields():
    """RawPseudoranges refuses optional fields of the wrong length, unknown system letters
    and GLONASS channels outside -7..6 (DataError naming the source)."""
    from mixnav.data import RawPseudoranges
    base = dict(week=np.array([2100]), tow=np.array([1.0]), epoch=np.array([0, 0]), prn=np.array([3, 4]),
                pseudorange=np.array([2e7, 2.1e7]), source="x.rnx")
    RawPseudoranges(**base, system=np.array(["G", "R"]), lli=np.zeros((2, 4), np.int8))
    for extra, message in [({"system": np.array(["G"])}, "system has shape"),
                           ({"system": np.array(["G", "Q"])}, "system letters"),
                           ({"lli": np.zeros((2, 3))}, "lli has shape"),
                           ({"carrier": np.zeros(3)}, "carrier has shape"),
                           ({"glonass_channels": {4: 7}}, "channel 7 is outside")]:
        with pytest.raises(DataError, match=message) as e:
            RawPseudoranges(**base, **extra)
        assert e.value.file == "x.rnx"


def test_signal_tables():
    """gnss/signals.py: systems and signals as given (letters, strings, lists), repeats
    dropped; wrong types and empty lists named; every default is a code of its system and
    version; companions replace the C."""
    from mixnav.gnss.signals import (DEFAULT_SIGNALS, SYSTEMS, check_signals, check_systems, code_error,
                                     companions)
    assert check_systems("GEG") == ("G", "E") and check_systems(["C"]) == ("C",)
    assert check_signals({"E": "C1X", "C": ["C2I", "C1I", "C2I"]}) == {"E": ("C1X",), "C": ("C2I", "C1I")}
    for bad, arg in [(None, "systems"), ("", "systems")]:
        with pytest.raises(ArgumentError) as e:
            check_systems(bad)
        assert e.value.argument == arg
    for bad, arg in [(["C1C"], "signals"), ({"E": []}, "signals.E"), ({"E": 5}, "signals.E"),
                     ({"G": "C1Q"}, "signals.G"), ({"R": "C1X"}, "signals.R"), ({"G": "C9"}, "signals.G")]:
        with pytest.raises(ArgumentError) as e:
            check_signals(bad)
        assert e.value.argument == arg
    for major, table in DEFAULT_SIGNALS.items():
        assert set(table) == set(SYSTEMS)
        for s, codes in table.items():
            assert all(code_error(s, c) is None and len(c) == major for c in codes), (s, codes)
    assert companions("C2I") == ("L2I", "D2I", "S2I") and companions("P1") == ("L1", "D1", "S1")
