"""RINEX observation input (issue 21): RINEX 2.11 and 3.03 files written here from the
android-static phone log, with other systems mixed in, read by io.rinex_obs and checked
against georinex's own parse of the same file, the SPP of the phone-log route, and bad
input (no pseudoranges, unknown systems, damaged epoch records, too few satellites)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mixnav.config import load_dataset
from mixnav.errors import DataError

from .conftest import data_file
from .test_process_raw import LOG, SHIPPED, _cfg, _write_rinex3

DOCS = Path(__file__).resolve().parents[1] / "docs"
GPS0 = np.datetime64("1980-01-06T00:00:00", "ns")
L1_WAVELENGTH = 299792458.0 / 1575.42e6
#: the default RINEX 2 observation types: 6 of them, so each record takes two lines
TYPES2 = ("C1", "L1", "D1", "S1", "P2", "L2")


def _time(week, tow):
    return GPS0 + np.timedelta64(int(round((week * 604800 + tow) * 1e9)), "ns")


def _write_rinex2(path, times, records, types=TYPES2, kind="M (MIXED)"):
    """A RINEX 2.11 observation file written here (the test's own file, not a vendored one).

    times : list of numpy datetime64 (one per epoch; GPS time)
    records : per epoch a list of (satellite name, {type: value}); a type absent is blank;
        an epoch may instead be ``("flag", n, lines)``: an event record (flag n, header lines).
    Lines are written without trailing blanks, as many receivers' converters do.
    """
    def fields(t):
        date, clock = str(t).split("T")
        y, mo, d = (int(x) for x in date.split("-"))
        hh, mm, ss = clock.split(":")
        return y, mo, d, int(hh), int(mm), float(ss)
    y, mo, d, hh, mm, ss = fields(times[0])
    tl = [f"{len(types):6d}" + "".join(f"{t:>6s}" for t in types[:9])]
    tl += [" " * 6 + "".join(f"{t:>6s}" for t in types[i:i + 9]) for i in range(9, len(types), 9)]
    head = [(f"     2.11           OBSERVATION DATA    {kind}", "RINEX VERSION / TYPE"),
            ("mixnav test", "PGM / RUN BY / DATE"), ("TEST", "MARKER NAME"),
            *[(t, "# / TYPES OF OBSERV") for t in tl],
            (f"{y:6d}{mo:6d}{d:6d}{hh:6d}{mm:6d}{ss:13.7f}     GPS", "TIME OF FIRST OBS"), ("", "END OF HEADER")]
    lines = [f"{a:<60s}{b:<20s}" for a, b in head]
    for t, recs in zip(times, records):
        y, mo, d, hh, mm, ss = fields(t)
        stamp = f" {y % 100:02d} {mo:2d} {d:2d} {hh:2d} {mm:2d}{ss:11.7f}  "
        if recs and recs[0] == "flag":
            _, flag, extra = recs
            lines.append(f"{stamp}{flag}{len(extra):3d}")
            lines += [f"{a:<60s}{b:<20s}" for a, b in extra]
            continue
        names = [n for n, _ in recs]
        lines.append(f"{stamp}0{len(names):3d}" + "".join(names[:12]))
        lines += [" " * 32 + "".join(names[i:i + 12]) for i in range(12, len(names), 12)]
        for _, vals in recs:
            cells = [f"{vals[t]:14.3f}  " if t in vals else " " * 16 for t in types]
            lines += ["".join(cells[i:i + 5]).rstrip() for i in range(0, len(cells), 5)]
    path.write_text("\n".join(lines) + "\n")


def _others(k):
    """Made-up records of other systems at epoch k: GLONASS R03, R14, Galileo E11, SBAS S20."""
    return [(name, 1.9e7 + 1000.0 * j + 0.5 * k) for j, name in enumerate(("R03", "R14", "E11", "S20"))]


def _phone_records(a, epochs=None, others=True):
    """Per epoch of the phone log ``a``: its GPS records (C1, L1 = C1 / lambda, S1 = C/N0)
    with the other systems' records interleaved (after the 2nd GPS satellite and at the end)."""
    out = []
    for k in range(len(a.tow) if epochs is None else epochs):
        sel = np.nonzero(a.epoch == k)[0]
        gps = [(f"G{int(a.prn[i]):02d}", {"C1": a.pseudorange[i], "L1": a.pseudorange[i] / L1_WAVELENGTH,
                                         "S1": round(float(a.cn0[i]), 3)}) for i in sel]
        oth = [(n, {"C1": r, "S1": 35.0}) for n, r in _others(k)] if others else []
        out.append(gps[:2] + oth[:2] + gps[2:] + oth[2:])
    return out


@pytest.fixture(scope="module")
def phone():
    """The android-static log read by io.android, its config and folder."""
    from mixnav.io.android import read_gnsslogger
    folder = data_file("android-static", LOG).parent
    ds, src, _ = load_dataset("android-static")
    a = read_gnsslogger(folder / LOG, max_sv_time_uncertainty_ns=ds.raw_gnss.max_sv_time_uncertainty * 1e9)
    return a, ds, src, folder


def _times(a, n=None):
    return [_time(a.week[k], a.tow[k]) for k in range(len(a.tow) if n is None else n)]


def _write_phone(path, a, n, version, extra=_others):
    """The first ``n`` epochs of the phone log ``a`` as a RINEX ``version`` (2 or 3) file, with
    the other systems' records ``extra(k)`` at epoch k (RINEX 2: :func:`_others`' always)."""
    if version == 2:
        _write_rinex2(path, _times(a, n), _phone_records(a, n))
    else:
        sel = a.epoch < n
        _write_rinex3(path, a.week[:n], a.tow[:n], a.epoch[sel], a.prn[sel], a.pseudorange[sel],
                      extra={k: extra(k) for k in range(n)})


def _georinex_gps(path, code):
    """{(epoch index, PRN): value} of every GPS satellite's ``code`` in georinex's own parse
    of the whole file (every system, default options), and georinex's dataset."""
    import georinex
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        warnings.simplefilter("ignore", RuntimeWarning)   # its interval of a system with no epochs
        g = georinex.load(path)
    vals = {}
    v = g[code].values
    for j, sv in enumerate(str(s) for s in g.sv.values):
        if sv.startswith("G"):
            for i in range(len(g.time)):
                if np.isfinite(v[i, j]):
                    vals[(i, int(sv[1:]))] = float(v[i, j])
    return vals, g


def _ns(week, tow):
    return GPS0 + (week.astype("int64") * 604800 * 10**9 + np.round(tow * 1e9).astype("int64")).astype("timedelta64[ns]")


@pytest.mark.parametrize("version", [2, 3])
def test_reader_matches_georinex_own_parse(tmp_path, phone, version):
    """Every GPS C1 / C1C value and PRN our reader returns, epoch by epoch, is georinex's own
    (whole-file, every-system) parse of the same file, one for one and exactly (both are
    the file's text as floats), and the phone log's to the file's rounding (1 mm). Epoch
    times: georinex truncates the seconds (RINEX 3 to 1 us; RINEX 2 to 1 ms when its
    file-size guess fails, as for these files with trailing blanks stripped; its float
    truncation can take one unit more, .999 -> .998999), so ours,
    read from the epoch records to the ns, are at most that much later than its and equal
    the written times to the file's 0.1 us. The other systems' records are counted per
    system letter, as many as written and as georinex finds for the systems it knows (the
    RINEX 3 file also has records of a letter its header does not list, X: georinex passes
    over them, we count them)."""
    from mixnav.io.rinex_obs import read_rinex_obs
    a = phone[0]
    n = 60
    path = tmp_path / f"mixed.{version}o"
    _write_phone(path, a, n, version, extra=lambda k: _others(k) + [("X05", 2.2e7)])
    if version == 3:
        # X: a system letter the header does not list (georinex passes over its records)
        text = path.read_text()
        path.write_text(text.replace(f"{'X    1 C1C':<60s}SYS / # / OBS TYPES \n", ""))
        assert "X    1" not in path.read_text() and "X05" in path.read_text()
    r = read_rinex_obs(path)
    code = "C1" if version == 2 else "C1C"
    assert r.code == code and int(r.version) == version
    ours = {(int(e), int(p)): float(v) for e, p, v in zip(r.epoch, r.prn, r.pseudorange)}
    theirs, g = _georinex_gps(path, code)
    assert len(ours) == len(theirs) == int((a.epoch < n).sum())
    assert ours.keys() == theirs.keys()
    assert all(ours[k] == theirs[k] for k in ours)
    late = (_ns(r.week, r.tow) - np.asarray(g.time.values, dtype="datetime64[ns]")).astype(np.int64)
    assert len(late) == n and late.min() >= 0 and late.max() <= (10**6 if version == 2 else 10**3), late.max()
    written = np.array(_times(a, n), dtype="datetime64[ns]")
    assert np.abs((_ns(r.week, r.tow) - written).astype(np.int64)).max() <= 50 + 1   # 0.1 us rounding
    # and the phone log's values, to the file's rounding
    sel = a.epoch < n
    np.testing.assert_allclose(r.pseudorange, a.pseudorange[sel], atol=5.1e-4)
    np.testing.assert_array_equal(r.prn, a.prn[sel])
    # other systems: counted per letter, matching what georinex itself finds for the known ones
    assert r.rejected == {"not GPS: E": n, "not GPS: R": 2 * n, "not GPS: S": n,
                          **({"not GPS: X": n} if version == 3 else {})}
    assert not any(str(x).startswith("X") for x in g.sv.values)
    for s in "ERS":
        found = int(np.isfinite(g[code].sel(sv=[x for x in g.sv.values if str(x).startswith(s)]).values).sum())
        assert found == r.rejected[f"not GPS: {s}"], s
    assert r.epochs_all_rejected == 0


def _process(ds, src, folder):
    from mixnav.experiment.spp_process import process_raw, solution_table
    po = process_raw(ds, src, folder)
    return po, solution_table(po)


def _rinex_config(tmp_path, phone, name, file):
    ds, folder = phone[1], phone[3]
    shutil.copy(folder / ds.raw_gnss.navigation, tmp_path)
    text = SHIPPED.replace('format = "android-gnsslogger"', 'format = "rinex-obs"').replace(
        f'file = "{LOG}"', f'file = "{file}"')
    assert file in text
    return load_dataset(_cfg(tmp_path, text, name))[:2]


def test_rinex2_route_gives_the_rinex3_and_phone_log_solution(tmp_path, phone):
    """The whole phone log as RINEX 2.11 (GLONASS, Galileo and SBAS records mixed in, 6
    observation types on two lines a record, satellite lists over 12 on continuation
    lines) and as RINEX 3.03: the same epochs solved and positions within 1 cm of each
    other and of the phone-log route at every epoch (the files' 1 mm / 1 us rounding moves a
    fix by millimetres); metrics.json counts the other systems per letter under
    ``measurements_rejected``, a key docs/outputs.md documents."""
    from mixnav.experiment.spp_process import write_raw
    a, ds, src, folder = phone
    _write_rinex2(tmp_path / "phone.16o", _times(a), _phone_records(a))
    _write_rinex3(tmp_path / "phone.rnx", a.week, a.tow, a.epoch, a.prn, a.pseudorange)
    assert any(len(ln) > 32 and ln.startswith(" " * 32) for ln in (tmp_path / "phone.16o").read_text().splitlines())
    ds2, src2 = _rinex_config(tmp_path, phone, "r2.toml", "phone.16o")
    ds3, src3 = _rinex_config(tmp_path, phone, "r3.toml", "phone.rnx")
    _, t_a = _process(ds, src, folder)
    po2, t_2 = _process(ds2, src2, tmp_path)
    _, t_3 = _process(ds3, src3, tmp_path)
    assert (t_a.status == t_2.status).all() and (t_a.status == t_3.status).all()
    ok = (t_a.status == "ok").to_numpy()
    assert ok.sum() > 200
    cols = ["err_n_m", "err_e_m", "err_d_m"]
    d2 = np.abs(t_2.loc[ok, cols].to_numpy() - t_a.loc[ok, cols].to_numpy()).max()
    d3 = np.abs(t_3.loc[ok, cols].to_numpy() - t_a.loc[ok, cols].to_numpy()).max()
    d23 = np.abs(t_2.loc[ok, cols].to_numpy() - t_3.loc[ok, cols].to_numpy()).max()
    print(f"max position difference: rinex2-phone {d2:.2e} m, rinex3-phone {d3:.2e} m, rinex2-rinex3 {d23:.2e} m")
    assert max(d2, d3, d23) < 0.01, (d2, d3, d23)
    m = write_raw(tmp_path / "out", po2)
    k = len(a.tow)
    assert m["measurements_rejected"] == {"not GPS: E": k, "not GPS: R": 2 * k, "not GPS: S": k}
    assert json.loads((tmp_path / "out" / "metrics.json").read_text())["measurements_rejected"]["not GPS: R"] == 2 * k
    doc = (DOCS / "outputs.md").read_text()
    assert "`measurements_rejected`" in doc and "`not GPS: <letter>`" in doc


def test_rinex_without_pseudoranges_is_a_data_error(tmp_path, phone):
    """No L1 C/A pseudorange: RINEX 2 with only L1/D1/S1 types, RINEX 3 whose GPS types are
    L1C/D1C/S1C, or a C1 column blank at every record: a DataError naming the file, and the
    header line of the observation types where that is the cause; a GLONASS-only file names
    the systems it found."""
    from mixnav.io.rinex_obs import read_rinex_obs
    a = phone[0]
    recs = _phone_records(a, 5)
    _write_rinex2(tmp_path / "nopr.16o", _times(a, 5), recs, types=("L1", "D1", "S1"))
    with pytest.raises(DataError, match=r"no L1 C/A pseudorange.*TYPES OF OBSERV lists L1 D1 S1") as e:
        read_rinex_obs(tmp_path / "nopr.16o")
    assert e.value.file.endswith("nopr.16o") and e.value.line == 4
    assert "TYPES OF OBSERV" in (tmp_path / "nopr.16o").read_text().splitlines()[3]
    text3 = tmp_path / "nopr.rnx"
    sel = a.epoch < 5
    _write_rinex3(text3, a.week[:5], a.tow[:5], a.epoch[sel], a.prn[sel], a.pseudorange[sel])
    text3.write_text(text3.read_text().replace("G    1 C1C", "G    3 L1C D1C S1C"))
    with pytest.raises(DataError, match=r"GPS \(C1C is needed\)") as e:
        read_rinex_obs(text3)
    assert e.value.file.endswith("nopr.rnx") and e.value.line == 4
    blank = [[(n, {t: v for t, v in vals.items() if t != "C1"}) for n, vals in ep] for ep in recs]
    _write_rinex2(tmp_path / "blank.16o", _times(a, 5), blank)
    with pytest.raises(DataError, match=r"C1 column is blank") as e:
        read_rinex_obs(tmp_path / "blank.16o")
    assert e.value.file.endswith("blank.16o")
    glo = [[(n, v) for n, v in ep if not n.startswith("G")] for ep in recs]
    _write_rinex2(tmp_path / "glo.16o", _times(a, 5), glo)
    with pytest.raises(DataError, match=r"no GPS satellite .* E: 5, R: 10, S: 5") as e:
        read_rinex_obs(tmp_path / "glo.16o")


def test_rinex_unknown_systems_few_satellites_and_damage_are_counted_or_named(tmp_path, phone):
    """A RINEX 2 file with records of a system letter georinex does not know ('X'), an
    epoch of GLONASS only, three epochs of 3 GPS satellites, an event record (flag 4)
    and a GPS record with a blank C1: each is counted (reader: ``not GPS: X``,
    ``no C1 pseudorange``, ``epochs_all_rejected``; SPP: ``too few satellites`` and
    ``all measurements rejected`` in metrics.json's epoch status), nothing vanishes; a
    damaged epoch record is a DataError naming its line."""
    from mixnav.experiment.spp_process import write_raw
    from mixnav.io.rinex_obs import read_rinex_obs
    a = phone[0]
    n = 40
    recs = _phone_records(a, n)
    times = _times(a, n)
    for k in range(n):
        recs[k].insert(1, ("X07", {"C1": 2.3e7, "S1": 30.0}))
    for k in (10, 11, 12):      # 3 GPS satellites: fewer than the 4 unknowns
        gps = [x for x in recs[k] if x[0].startswith("G")]
        recs[k] = [x for x in recs[k] if not x[0].startswith("G")] + gps[:3]
    recs[20] = [x for x in recs[20] if not x[0].startswith("G")]     # no GPS at all
    n_gps_20 = int((a.epoch == 20).sum())
    name, vals = recs[30][0]
    assert name.startswith("G")
    recs[30][0] = (name, {t: v for t, v in vals.items() if t != "C1"})   # blank C1
    times.insert(25, times[25] - np.timedelta64(500, "ms"))
    recs.insert(25, ("flag", 4, [("event record written by the test", "COMMENT")]))
    _write_rinex2(tmp_path / "odd.16o", times, recs)
    r = read_rinex_obs(tmp_path / "odd.16o")
    n_gps = int((a.epoch < n).sum())
    assert r.rejected["not GPS: X"] == n and r.rejected["not GPS: R"] == 2 * n
    assert r.rejected["no C1 pseudorange"] == 1
    assert r.epochs_all_rejected == 1 and len(r) == n - 1
    assert len(r.pseudorange) == n_gps - n_gps_20 - 1 - sum(int((a.epoch == k).sum()) - 3 for k in (10, 11, 12))
    ds, src = _rinex_config(tmp_path, phone, "odd.toml", "odd.16o")
    po, t = _process(ds, src, tmp_path)
    m = write_raw(tmp_path / "out", po)
    assert len(t) == n - 1 and (t.status == "too few satellites").sum() == 3
    assert m["epoch_status"]["too few satellites"] == 3
    assert m["epoch_status"]["all measurements rejected"] == 1
    assert m["epochs_total"] == n and m["epochs_used"] + m["epochs_skipped"] == n
    assert m["measurements_rejected"]["not GPS: X"] == n
    # a damaged epoch record: the line is named
    lines = (tmp_path / "odd.16o").read_text().splitlines()
    j = next(i for i, ln in enumerate(lines) if ln.startswith(" 16") and i > 40)
    lines[j] = "garbage where an epoch record must be"
    (tmp_path / "bad.16o").write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match="epoch record") as e:
        read_rinex_obs(tmp_path / "bad.16o")
    assert e.value.line == j + 1 and e.value.file.endswith("bad.16o")


def _line_of(lines, start, after=0):
    return next(i for i, ln in enumerate(lines) if ln.startswith(start) and i >= after)


def _glo_time(lines):
    j = next(i for i, ln in enumerate(lines) if "TIME OF FIRST OBS" in ln)
    lines[j] = lines[j][:48] + "GLO" + lines[j][51:]
    return j


def _more_types(lines):
    j = next(i for i, ln in enumerate(lines) if "# / TYPES OF OBSERV" in ln)
    lines[j] = "     7" + lines[j][6:]
    return j


def _short_sat_list(lines):
    j = _line_of(lines, " 16", 8)
    lines[j] = lines[j][:41]
    return j


def _repeated_time(lines):
    epochs = [i for i, ln in enumerate(lines) if ln.startswith(" 16")]
    lines[epochs[3]] = lines[epochs[2]][:26] + lines[epochs[3]][26:]
    return epochs[3]


def _no_end(lines):
    j = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    del lines[j]
    return None


def _blank_record(lines):
    j = _line_of(lines, ">") + 2
    lines[j] = ""
    return j


def _nav_type(lines):
    lines[0] = lines[0][:20] + "N" + lines[0][21:]
    return 0


@pytest.mark.parametrize("version, damage, message", [
    (2, _glo_time, "GLO time"), (2, _more_types, "declares 7 observation types but lists 6"),
    (2, _short_sat_list, "satellite list"), (2, _repeated_time, "do not increase"),
    (2, _no_end, "no END OF HEADER"), (3, _blank_record, "satellite record"),
    (3, _repeated_time, "do not increase"), (3, _nav_type, "not a RINEX 2 or 3 observation file"),
])
def test_damaged_rinex_names_file_and_line(tmp_path, phone, version, damage, message):
    """A damaged header or epoch record is a DataError naming the file and the line (1-based)
    of the damage: times in GLONASS time (GPS time needs no leap seconds), a type count that
    disagrees with the types listed, a satellite list shorter than its count, a repeated
    epoch time, no END OF HEADER, a blank satellite record (RINEX 3), a navigation file."""
    from mixnav.io.rinex_obs import read_rinex_obs
    a = phone[0]
    path = tmp_path / f"d.{version}o"
    if version == 2:
        _write_rinex2(path, _times(a, 6), _phone_records(a, 6))
    else:
        sel = a.epoch < 6
        _write_rinex3(path, a.week[:6], a.tow[:6], a.epoch[sel], a.prn[sel], a.pseudorange[sel])
    lines = path.read_text().splitlines()
    if damage is _repeated_time and version == 3:
        epochs = [i for i, ln in enumerate(lines) if ln.startswith(">")]
        lines[epochs[3]] = lines[epochs[2]][:29] + lines[epochs[3]][29:]
        j = epochs[3]
    else:
        j = damage(lines)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=message) as e:
        read_rinex_obs(path)
    assert e.value.file == str(path)
    if j is not None:
        assert e.value.line == j + 1, str(e.value)


def _epoch_lines(lines, version):
    """Indices of the observation epoch records (flag 0) of a file's ``lines`` written here."""
    if version >= 3:
        return [i for i, ln in enumerate(lines) if ln.startswith(">")]
    return [i for i, ln in enumerate(lines) if len(ln) > 31 and ln[28:29] == "0" and ln[26:27] == " "
            and ln[1:3].strip().isdigit() and ln[29:32].strip().isdigit() and ln[32:33].isalpha()]


def _with_events(lines, version):
    """``lines`` of an observation file with, before its 20th epoch, an external-event record
    (flag 5, one comment line) and a header-information record (flag 4), and after its 10th
    epoch a cycle-slip record (flag 6) of its first two satellites at that epoch's time."""
    at = _epoch_lines(lines, version)
    out = list(lines)
    i20, i10, i11 = at[20], at[10], at[11]
    head = lines[i20]
    comment = f"{'event written by the test':<60s}{'COMMENT':<20s}"
    if version >= 3:
        ev5, ev4 = head[:31] + "5  1", head[:31] + "4  1"
        slip = [lines[i10][:31] + "6  2"] + lines[i10 + 1:i10 + 3]
    else:
        per_sat = (i11 - i10 - 1) // int(lines[i10][29:32])
        ev5, ev4 = head[:28] + "5  1", head[:28] + "4  1"
        slip = [lines[i10][:28] + "6  2" + lines[i10][32:38]] + lines[i10 + 1:i10 + 1 + 2 * per_sat]
    out[i20:i20] = [ev5, comment, ev4, comment]
    out[i11:i11] = slip
    return out


@pytest.mark.parametrize("version", [2, 3])
def test_event_and_cycle_slip_records_are_skipped_and_counted(tmp_path, phone, version):
    """Epoch flags 2-5 (events) and 6 (cycle-slip records, laid out as observations at an
    observation epoch's time) are not observations: the file with them reads exactly as the
    file without them, and they are counted per flag. georinex alone reads the flag-6 record
    as a second epoch at the same time and fails, and lost an observation epoch after a
    flag-5 record, so it is given the file without them."""
    from mixnav.io.rinex_obs import read_rinex_obs
    a = phone[0]
    n = 40
    plain = tmp_path / f"plain.{version}o"
    _write_phone(plain, a, n, version)
    lines = plain.read_text().splitlines()
    events = tmp_path / f"events.{version}o"
    events.write_text("\n".join(_with_events(lines, version)) + "\n")
    assert len(events.read_text().splitlines()) == len(lines) + 4 + (5 if version == 2 else 3)
    r0, r = read_rinex_obs(plain), read_rinex_obs(events)
    assert len(r) == len(r0) == n
    for name in ("week", "tow", "epoch", "prn", "pseudorange"):
        np.testing.assert_array_equal(getattr(r, name), getattr(r0, name), err_msg=name)
    assert r.rejected == r0.rejected and r.epochs_all_rejected == r0.epochs_all_rejected
    assert r0.event_records == {} and r.event_records == {"flag 4": 1, "flag 5": 1, "flag 6": 1}
