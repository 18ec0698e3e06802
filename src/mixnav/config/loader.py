"""Load scenario files (TOML) by shipped name or by path, with located errors."""

from __future__ import annotations

import re
import tomllib

import numpy as np
from importlib import resources
from pathlib import Path

from pydantic import ValidationError

from ..errors import ConfigError
from ..ins.imu_model import ImuErrorModel
from .scenario_schema import Scenario

def _shipped_dir(folder: str = "scenarios"):
    return resources.files("mixnav.config").joinpath(folder)


def _list(folder: str, table: str) -> dict[str, str]:
    out = {}
    for entry in sorted(_shipped_dir(folder).iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            data = tomllib.loads(entry.read_text(encoding="utf-8"))
            out[entry.name[:-5]] = data.get(table, {}).get("description", "")
    return out


def list_scenarios() -> dict[str, str]:
    """Names and one-line descriptions of the scenarios shipped with mixnav."""
    return _list("scenarios", "scenario")


def list_datasets() -> dict[str, str]:
    """Names and descriptions of the real-data configs shipped with mixnav."""
    return _list("datasets", "dataset")


def resolve(name_or_path: str, folder: str = "scenarios", kind: str = "scenario") -> tuple[str, str]:
    """The text of a config and the name to cite it by in errors."""
    if not isinstance(name_or_path, str) or not name_or_path or "\x00" in name_or_path:
        raise ConfigError(f"not a {kind} name or file path: {name_or_path!r}")
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ConfigError(f"no such {kind} file", file=str(p))
        return read_config_text(p, kind), str(p)
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.+-]*", name_or_path):
        raise ConfigError(f"no such {kind} file, and not a shipped {kind} name: {name_or_path!r}")
    entry = _shipped_dir(folder).joinpath(f"{name_or_path}.toml")
    if not entry.is_file():
        known = ", ".join(_list(folder, kind))
        raise ConfigError(f"unknown {kind} '{name_or_path}'; shipped: {known} "
                          "(or give the path of a .toml file)")
    return entry.read_text(encoding="utf-8"), f"{name_or_path}.toml (shipped)"


#: largest config file read (bytes): a scenario or dataset file is a few kB
MAX_CONFIG_BYTES = 10_000_000


def read_config_text(p: Path, kind: str = "config") -> str:
    """The text of a config file; unreadable, binary, oversized or non-UTF-8 files are
    ConfigErrors naming the file (and the byte offset of a bad byte)."""
    try:
        size = p.stat().st_size
        if size > MAX_CONFIG_BYTES:
            raise ConfigError(f"{size} bytes is too large for a {kind} file "
                              f"(at most {MAX_CONFIG_BYTES})", file=str(p))
        data = p.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read the {kind} file: {exc.strerror or exc}", file=str(p)) from None
    nul = data.find(bytes(1))
    if nul >= 0:
        raise ConfigError(f"line {data[:nul].count(10) + 1}: a binary file, not a TOML {kind} file (NUL byte at "
                          f"offset {nul})", file=str(p))
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise ConfigError(f"line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                          f"{exc.start}); save the file as UTF-8", file=str(p)) from None


def _key(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("static", "uniform", "accelerate", "turn", "climb") and out.endswith("]"):
            continue  # the discriminated-union tag pydantic puts in the path
        else:
            out += ("." if out else "") + str(part)
    return out


def load_scenario(name_or_path: str) -> tuple[Scenario, str, str]:
    """Parse and validate a scenario.

    Returns
    -------
    scenario : Scenario
        Validated, in SI units.
    source : str
        The file it came from (for messages and reports).
    text : str
        The file's text (for the report).

    Raises
    ------
    ConfigError
        Naming the file and the dotted key of the first problem.
    """
    text, source = resolve(name_or_path)
    sc = _validate(Scenario, text, source)
    _check_scenario(sc, source)
    if sc.sweep is not None:
        sweep_variants(sc, text, source)  # a bad sweep value fails at load time
    return sc, source, text


def _check_scenario(sc, source: str) -> None:
    """What the schema alone cannot check: IMU models and noise tables build."""
    _check_imu_rate(sc, source)   # first: the checks below divide by it (or by the GNSS rate into it)
    _check_imu_models(sc, source)
    gnss_noise(sc, source)
    imu_white_noise(sc, source)
    _check_hold(sc, source)
    observable_noise(sc, source)
    _check_odometer(sc, source)
    _check_windows(sc, source)


#: plausibility limits of a simulated run (docs/validation.md): the IMU rate, the samples of one
#: run (memory: about 200 bytes each), a segment's turn or pitch rate, a lever arm's component
MAX_IMU_RATE = 10e3
MIN_IMU_RATE = 1.0
MAX_IMU_SAMPLES = 20_000_000
MAX_SEGMENT_RATE = float(np.radians(2000.0))
MAX_LEVER = 100.0


def check_lever(v, source, key) -> None:
    """A lever arm or installation position [m] within +-:data:`MAX_LEVER` per component."""
    if v is not None and not np.all(np.abs(np.asarray(v, float)) <= MAX_LEVER):
        raise ConfigError(f"{[float(x) for x in v]} m: a component beyond {MAX_LEVER:g} m is not on a vehicle",
                          file=source, key=key)


def _check_imu_rate(sc, source) -> None:
    """``imu.rate`` within :data:`MIN_IMU_RATE`..:data:`MAX_IMU_RATE`, named itself (an absurd
    IMU rate was blamed on ``gnss.rate``, which must divide it)."""
    if not MIN_IMU_RATE <= sc.imu.rate <= MAX_IMU_RATE:
        raise ConfigError(f"{sc.imu.rate:g} Hz is outside {MIN_IMU_RATE:g}..{MAX_IMU_RATE:g} Hz (an inertial "
                          "navigation rate)", file=source, key="imu.rate")


def _check_windows(sc, source) -> None:
    """GNSS fixes fall on IMU samples; outage windows and scored segments lie inside the run; the run fits in
    memory; segments turn no faster than a gyro measures; lever arms (docs/validation.md)."""
    if sc.imu.rate * sc.duration > MAX_IMU_SAMPLES:
        raise ConfigError(f"{sc.duration:g} s at {sc.imu.rate:g} Hz is {sc.imu.rate * sc.duration:.3g} IMU samples; "
                          f"at most {MAX_IMU_SAMPLES:.0e} per run", file=source, key="trajectory.segments")
    for i, seg in enumerate(sc.trajectory.segments):
        rate = getattr(seg, "rate", None)
        if isinstance(rate, float) and not abs(rate) <= MAX_SEGMENT_RATE:
            raise ConfigError(f"turns at {np.degrees(rate):.4g} deg/s, beyond {np.degrees(MAX_SEGMENT_RATE):g} deg/s "
                              "(no vehicle, and no gyro, does)", file=source, key=f"trajectory.segments[{i}]")
    check_lever(sc.gnss.lever_arm, source, "gnss.lever_arm")
    step = sc.imu.rate / sc.gnss.rate
    if round(step) < 1 or abs(step - round(step)) > 1e-9 * step:
        raise ConfigError(f"GNSS rate {sc.gnss.rate:g} Hz must divide the IMU rate ({sc.imu.rate:g} Hz): fixes fall "
                          "on IMU samples", file=source, key="gnss.rate")
    end = sc.duration
    for i, (a, b) in enumerate(sc.gnss.outages):
        if a >= end or b > end + 1e-9:
            raise ConfigError(f"outage [{a:g}, {b:g}] s reaches beyond the end of the run ({end:g} s)",
                              file=source, key=f"gnss.outages[{i}]")
    seen: dict[str, int] = {}
    for i, (name, a, b) in enumerate(sc.scored_segments):
        if a >= end or b > end + 1e-9:
            raise ConfigError(f"segment '{name}' [{a:g}, {b:g}] s reaches beyond the end of the run ({end:g} s)",
                              file=source, key=f"scoring.segments[{i}]")
        if name in seen:
            raise ConfigError(f"segment name '{name}' is used by scoring.segments[{seen[name]}] too: names "
                              "must differ", file=source, key=f"scoring.segments[{i}].name")
        seen[name] = i


def _check_odometer(sc, source) -> None:
    """``odometer.rate``: samples fall on IMU samples (the IMU rate a whole multiple of it);
    no ``aiding.odometer.time_offset`` (a simulated odometer's stamps are exact)."""
    a = sc.aiding.odometer if sc.aiding is not None else None
    if a is not None and a.time_offset:
        raise ConfigError("a simulated odometer's stamps are exact: time_offset is for a dataset's speeds file",
                          file=source, key="aiding.odometer.time_offset")
    o = sc.odometer
    if o is None:
        return
    step = sc.imu.rate / o.rate
    if abs(step - round(step)) > 1e-9 * step or round(step) < 1:
        raise ConfigError(f"odometer rate {o.rate:g} Hz must divide the IMU rate ({sc.imu.rate:g} Hz): "
                          "odometer samples fall on IMU samples", file=source, key="odometer.rate")


def _check_hold(sc, source) -> None:
    """``imu.white_noise_hold``: a whole number of IMU intervals, no longer than the run."""
    from ..ins.imu_model import check_hold
    if sc.imu.white_noise_hold is None:
        return
    try:
        check_hold(sc.imu.white_noise_hold, 1.0 / sc.imu.rate, sc.duration)
    except ConfigError as exc:
        raise ConfigError(exc.message, file=source, key="imu.white_noise_hold") from None


def observable_noise(sc, source):
    """Noise processes of the raw observables ``(pseudorange, range rate, carrier)``;
    each None when not given (or when the scenario has no satellites)."""
    from .. import units as u
    from .noise_spec import from_config
    s = sc.gnss.satellites
    if s is None:
        return None, None, None
    dims = (("pseudorange_noise", u.LENGTH), ("range_rate_noise", u.VELOCITY),
            ("carrier_noise", u.LENGTH))
    return tuple(None if getattr(s, k) is None else
                 from_config(getattr(s, k), d, f"gnss.satellites.{k}", source) for k, d in dims)


_KEY_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)$")


def _set_dotted(data: dict, key: str, value, source: str, where: str) -> None:
    """Replace ``data[a][b][i]...`` named by the dotted ``key`` (``a.b[i].c``) with ``value``.

    Every table and list on the way must exist (a typo is an error); the last
    name may be new, so a sweep can add an optional key (its schema checks it).
    """
    parts = key.split(".")
    node = data
    for n, part in enumerate(parts):
        m = _KEY_PART.match(part)
        if m is None:
            raise ConfigError(f"'{key}' is not a dotted key such as 'gnss.position_noise.weights' "
                              "or 'methods[0].states'", file=source, key=where)
        name, idx = m.group(1), [int(i) for i in re.findall(r"\d+", m.group(2))]
        last = n == len(parts) - 1
        if not isinstance(node, dict):
            raise ConfigError(f"'{'.'.join(parts[:n])}' is not a table", file=source, key=where)
        if (not last or idx) and name not in node:
            raise ConfigError(f"the scenario has no key '{'.'.join(parts[:n + 1])}'", file=source,
                              key=where)
        if not idx and last:
            node[name] = value
            return
        if not idx:
            node = node[name]
            continue
        node = node[name]
        for j, i in enumerate(idx):
            if not isinstance(node, list) or i >= len(node):
                raise ConfigError(f"'{key}': index {i} is out of range", file=source, key=where)
            if last and j == len(idx) - 1:
                node[i] = value
                return
            node = node[i]


def sweep_variants(sc: Scenario, text: str, source: str) -> list[tuple[float, Scenario]]:
    """The scenario once per sweep value: ``[(value, scenario), ...]``.

    Without a sweep: ``[(nan, sc)]``. Each variant is the file's TOML with the
    ``sweep.set`` keys replaced and the ``sweep`` table removed, validated in
    full; an error names the sweep entry (``sweep.set."KEY"[i]``) and the
    problem the schema found.
    """
    import copy
    if sc.sweep is None:
        return [(float("nan"), sc)]
    base = tomllib.loads(text)
    base.pop("sweep")
    out = []
    for i, value in enumerate(sc.sweep.values):
        data = copy.deepcopy(base)
        for key, vals in sc.sweep.set.items():
            _set_dotted(data, key, copy.deepcopy(vals[i]), source, f'sweep.set."{key}"[{i}]')
        where = f"sweep value {value:g} ({sc.sweep.name})"
        try:
            variant = _validate_data(Scenario, data, source)
            _check_scenario(variant, source)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc.message}", file=source, key=exc.key) from None
        out.append((float(value), variant))
    return out


def imu_white_noise(sc, source):
    """The scenario's IMU white-noise process (dimensionless), or None."""
    from .. import units as u
    from .noise_spec import from_config
    w = sc.imu.white_noise
    return None if w is None else from_config(w, u.DIMENSIONLESS, "imu.white_noise", source)


def gnss_noise(sc, source):
    """The scenario's GNSS position and velocity noise processes (or None)."""
    from .. import units as u
    from .noise_spec import from_config
    g = sc.gnss
    pos = None if g.position_noise is None else from_config(g.position_noise, u.LENGTH, "gnss.position_noise",
                                                            source)
    vel = None if g.velocity_noise is None else from_config(g.velocity_noise, u.VELOCITY, "gnss.velocity_noise",
                                                            source)
    return pos, vel


def _check_imu_models(cfg, source: str) -> None:
    """Build every IMU model of a config once, so a bad value fails at load time."""
    imu_model(cfg.imu.grade, cfg.imu.errors, source, "imu.errors", "imu.grade")
    for i, m in enumerate(cfg.methods):
        if m.imu_grade is not None or m.imu_errors is not None:
            imu_model(m.imu_grade, m.imu_errors or {}, source, f"methods[{i}].imu_errors",
                      f"methods[{i}].imu_grade")


def _validate(model, text: str, source: str):
    """Parse TOML text and validate it against ``model``; errors name file and key."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"not valid TOML: {exc}", file=source) from None
    return _validate_data(model, data, source)


def _key_in_message(model, msg: str) -> str:
    """The top-level key a whole-file check talks about (its error has no location):
    the first field of ``model`` (or its singular) that the message names."""
    best = None
    for name in model.model_fields:
        for word in (name, name[:-1] if name.endswith("s") else name):
            m = re.search(rf"\b{re.escape(word)}\b", msg)
            if m and (best is None or m.start() < best[0]):
                best = (m.start(), name)
    return "" if best is None else best[1]


def _validate_data(model, data: dict, source: str):
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        key = _key(err["loc"]) or _key_in_message(model, err["msg"])
        msg = {"extra_forbidden": "unknown key (check the spelling against docs/scenarios.md)",
               "missing": "required key is missing"}.get(err["type"], err["msg"])
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        sub = re.match(r"options\.([\w.]+): ", msg)
        if sub and key.endswith("options"):     # an option the estimator's model refused: its own key
            key, msg = f"{key}.{sub.group(1)}", msg[sub.end():]
        more = f" (and {len(exc.errors()) - 1} more problem(s))" if len(exc.errors()) > 1 else ""
        raise ConfigError(msg + more, file=source, key=key) from None


def load_dataset(name_or_path: str):
    """Parse and validate a real-data config (``mixnav process``).

    Returns ``(dataset, source, text)`` like :func:`load_scenario`.
    """
    text, source = resolve(name_or_path, "datasets", "dataset")
    return load_dataset_text(text, source)


#: the dataset kinds whose schemas this module knows itself (the others: register_dataset_schema)
BUILT_IN_DATASET_KINDS = ("ins-gnss", "gnss-raw", "odometry-gnss")
#: dataset kind -> the pydantic model its files validate against (kinds added from outside)
_DATASET_SCHEMAS: dict = {}


def register_dataset_schema(kind: str, schema) -> None:
    """Validate dataset files whose ``dataset.kind`` is ``kind`` with the pydantic model
    ``schema`` (a new kind's; its errors name the file and key as the built-in schemas' do).
    :func:`mixnav.experiment.pipelines.register_pipeline` calls it with the kind's pipeline.
    A built-in kind, or a kind registered already, is a ValueError."""
    if kind in BUILT_IN_DATASET_KINDS or kind in _DATASET_SCHEMAS:
        raise ValueError(f"dataset kind '{kind}' has a schema already")
    _DATASET_SCHEMAS[kind] = schema


def load_dataset_text(text: str, source: str):
    """:func:`load_dataset` of a dataset file's text (``source``: the file it stands for:
    its relative ``data_dir`` resolves from there, and errors name it). Returns
    ``(dataset, source, text)``."""
    from .dataset_schema import Dataset
    kind = _declared_kind(text)
    if kind in _DATASET_SCHEMAS:   # a kind added by register_dataset_schema
        return _validate(_DATASET_SCHEMAS[kind], text, source), source, text
    if kind == "odometry-gnss":   # its own schema (config/vehicle_schema.py)
        from .vehicle_schema import VehicleDataset
        return _validate(VehicleDataset, text, source), source, text
    if kind == "gnss-raw":   # its own schema (config/raw_gnss_schema.py)
        from .raw_gnss_schema import FOREIGN_SECTIONS, RawGnssDataset
        import tomllib
        data = tomllib.loads(text)
        for key in FOREIGN_SECTIONS:   # said as such, not as an unknown key: the kind is what is wrong
            if key in data:
                raise ConfigError(f"not used by dataset.kind = '{kind}' (remove it, or change the kind)",
                                  file=source, key=key)
        ds = _validate_data(RawGnssDataset, data, source)
        if ds.reference is not None and ds.reference_point is not None:
            # two truths would score the same epochs twice, differently: one of them is a slip
            raise ConfigError("give either [reference_point] (a static receiver's surveyed point) or [reference] "
                              "(a moving receiver's trajectory), not both", file=source, key="reference")
        if ds.reference is not None and (ds.reference.format == "smartloc") != (ds.raw_gnss.format == "smartloc"):
            # a smartLoc log and its ground truth count seconds from the log's start; every other file GPS time
            raise ConfigError(f"a reference in format \"{ds.reference.format}\" cannot score raw_gnss format "
                              f"\"{ds.raw_gnss.format}\": smartLoc files (log and ground truth) count seconds from the "
                              "start of the log, every other format GPS time; use the smartLoc ground truth with "
                              "a smartLoc log only", file=source, key="reference.format")
        return ds, source, text
    ds = _validate(Dataset, text, source)
    _check_kind(ds, source)
    _check_imu_models(ds, source)
    corruption(ds, source)
    for k in ("imu_position", "antenna_position"):
        check_lever(getattr(ds.installation, k), source, f"installation.{k}")
    return ds, source, text


def _declared_kind(text: str):
    """``dataset.kind`` as written (None when the text is not TOML or has none: the full
    validation then reports it)."""
    import tomllib
    try:
        return tomllib.loads(text).get("dataset", {}).get("kind")
    except (tomllib.TOMLDecodeError, AttributeError):
        return None


def _check_kind(ds, source):
    """Each dataset kind has its sections (dataset_schema.KIND_SECTIONS)."""
    from .dataset_schema import KIND_SECTIONS
    kind = ds.dataset.kind
    needed, foreign = KIND_SECTIONS[kind]
    for key in needed:
        if getattr(ds, key) is None:
            raise ConfigError(f"required key is missing (dataset.kind = '{kind}')", file=source, key=key)
    for key in foreign:
        if getattr(ds, key) is not None:
            raise ConfigError(f"not used by dataset.kind = '{kind}' (remove it, or change the kind)",
                              file=source, key=key)
    if ds.gnss is None and ds.raw_gnss is None:
        raise ConfigError("required key is missing: the GNSS as fixes ([gnss]) or as a RINEX observation and "
                          "navigation file ([raw_gnss])", file=source, key="gnss")
    if ds.gnss is not None and ds.raw_gnss is not None:
        raise ConfigError("give the GNSS either as fixes ([gnss]) or as raw RINEX observations ([raw_gnss]), "
                          "not both", file=source, key="raw_gnss")
    if ds.raw_gnss is not None:
        for i, m in enumerate(ds.methods or []):
            if m.type in ("tight-ekf", "tdcp-ekf") and m.states in (15, 21):
                raise ConfigError(f"method '{m.name}' is tightly coupled: it needs the receiver clock states "
                                  "(states = 17, or 23 with the scale factors)", file=source, key=f"methods[{i}].states")


def corruption(ds, source):
    """The noise process added to a dataset's recorded fixes (or None)."""
    from .. import units as u
    from .noise_spec import from_config
    if ds.gnss is None:
        return None
    c = ds.gnss.corrupt_position
    return None if c is None else from_config(c, u.LENGTH, "gnss.corrupt_position", source)


def imu_model(grade, errors, source, prefix, grade_key) -> ImuErrorModel:
    """The IMU error model of a grade plus overrides, errors located at ``prefix``."""
    return ImuErrorModel.from_datasheet(errors, grade=grade, source=source, key_prefix=prefix,
                                        grade_key=grade_key)
