"""The reader registry and the pipeline dispatch table: every kind the dataset schemas accept
has a pipeline, the registered formats are the ones the schemas and the docs list, and a
reader is chosen (and given its options) by the table's format."""

import re
import sys
import typing
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pydantic
import pytest

from mixnav.config import aiding_schema, dataset_schema, raw_gnss_schema, vehicle_schema
from mixnav.data import ImuData, RawPseudoranges
from mixnav.errors import ConfigError, DataError
from mixnav.experiment import pipelines
from mixnav.io import registry
from mixnav.io.readers import KIND_TYPES, formats, get_reader, read_table

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _literal(model, field="format") -> set:
    return set(typing.get_args(model.model_fields[field].annotation))


#: the schema fields that take any reader of their kind (config.fields.reader_format: the readers'
#: own registrations, read by mixnav.formats): a new reader of these kinds is its module only
REGISTRY_FIELDS = {
    "imu": [dataset_schema.ImuFile],
    "gnss-fixes": [dataset_schema.GnssFile],
    "raw-gnss": [dataset_schema.RawGnss],
    "odometer": [aiding_schema.OdometerAidingConfig],
    "reference": [dataset_schema.ReferenceFile],
}
#: the fields that list what their pipeline can do with a kind (a subset of its readers)
SUBSET_FIELDS = {
    "raw-gnss": _literal(dataset_schema.InsRawGnss) | _literal(vehicle_schema.Pseudoranges),
    "odometry": _literal(vehicle_schema.OdometryFile),
    "reference": _literal(vehicle_schema.VehicleReference) | _literal(raw_gnss_schema.RawReference),
}


def _accepts(model, value) -> bool:
    field = model.model_fields["format"]
    try:
        pydantic.TypeAdapter(typing.Annotated[(field.annotation, *field.metadata)]).validate_python(value)
    except pydantic.ValidationError:
        return False
    return True


def test_registered_formats_are_the_schemas_formats():
    assert set(KIND_TYPES) == set(REGISTRY_FIELDS) | set(SUBSET_FIELDS)
    for kind, models in REGISTRY_FIELDS.items():
        for model in models:
            assert all(_accepts(model, f) for f in formats(kind)), (kind, model)
            assert not _accepts(model, "no-such-format")
    for kind, listed in SUBSET_FIELDS.items():
        assert listed <= set(formats(kind)), kind
    assert set(formats("odometry")) == SUBSET_FIELDS["odometry"]


def test_a_new_reader_is_its_module_only(tmp_path, monkeypatch):
    """A reader module dropped into io/ is found from its source (the config accepts its format at
    load time, nothing imported) and imported when a file names the format; a format of no
    module is refused by the schema naming the registered ones."""
    from mixnav import formats as known
    folder = tmp_path / "io"
    folder.mkdir()
    (folder / "sbg.py").write_text('from mixnav.io.registry import register_reader\n\n\n'
                                   '@register_reader("imu", "sbg-log")\ndef read(path, options):\n    pass\n')
    assert known.find_readers(folder, "pkg") == {("imu", "sbg-log"): "pkg.sbg"}
    monkeypatch.setattr(known, "builtin_readers", lambda: {**known.find_readers(folder, "pkg"),
                                                           ("imu", "psins"): "mixnav.io.psins"})
    monkeypatch.setattr(known, "_ADDED", {})      # as in a process that has imported no reader yet
    assert known.known_formats("imu") == ("sbg-log", "psins")
    assert _accepts(dataset_schema.ImuFile, "sbg-log")
    with pytest.raises(pydantic.ValidationError, match=r"unknown imu format 'xsens' \(registered: sbg-log, psins\)"):
        dataset_schema.ImuFile(format="xsens", file="x")
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "sbg.py").write_text((folder / "sbg.py").read_text())
    monkeypatch.setattr(registry, "_READERS", dict(registry._READERS))
    assert "pkg.sbg" not in sys.modules
    assert get_reader("imu", "sbg-log").format == "sbg-log" and "pkg.sbg" in sys.modules


def test_the_builtin_readers_are_found_in_their_modules():
    """Every built-in reader is registered by the module mixnav.formats read it from."""
    from mixnav import formats as known
    for (kind, fmt), module in known.builtin_readers().items():
        reader = get_reader(kind, fmt)
        assert reader.function.__module__ == module, (kind, fmt)


def test_registered_formats_are_the_docs_formats():
    text = (DOCS / "data_formats.md").read_text()
    rows = re.findall(r"^\| `([a-z-]+)` \| ((?:`[a-z0-9-]+`(?:, )?)+) \| `(\w+)`", text, re.M)
    documented = {kind: {f.strip("`") for f in fmts.split(", ")} for kind, fmts, _ in rows}
    assert documented == {k: set(formats(k)) for k in KIND_TYPES}
    assert {kind: t for kind, _, t in rows} == {k: v.__name__ for k, v in KIND_TYPES.items()}
    # every format of the docs' per-format tables is a registered one
    named = set(re.findall(r"^\| `([a-z0-9-]+)` \| `io\.", text, re.M))
    assert named and named <= {f for k in KIND_TYPES for f in formats(k)}


def test_unknown_format_names_the_key_and_the_registered_formats():
    with pytest.raises(ConfigError) as exc:
        read_table("imu", SimpleNamespace(format="sbg", file="x.bin"), Path("."), "imu")
    assert exc.value.key == "imu.format"
    for f in formats("imu"):
        assert f in str(exc.value)


def test_a_reader_returns_its_kinds_type(monkeypatch):
    from mixnav import formats as known
    monkeypatch.setattr(registry, "_READERS", dict(registry._READERS))
    monkeypatch.setattr(known, "_ADDED", dict(known._ADDED))
    registry.register_reader("imu", "wrong")(lambda path, options: "not ImuData")
    with pytest.raises(TypeError, match="ImuData"):
        get_reader("imu", "wrong")(Path("x"))
    with pytest.raises(ValueError, match="registered already"):
        registry.register_reader("imu", "wrong")(lambda path, options: None)
    with pytest.raises(ValueError, match="unknown data kind"):
        registry.register_reader("sonar", "x")


def test_raw_gnss_readers_share_one_type():
    from mixnav.io import android, rinex_obs
    assert android.AndroidPseudoranges is rinex_obs.RinexPseudoranges is RawPseudoranges is KIND_TYPES["raw-gnss"]


def _imu_csv(path: Path, gap: bool) -> Path:
    t = np.arange(0.0, 2.0, 0.01)
    if gap:
        t = np.concatenate([t[:100], t[100:] + 1.0])
    lines = ["time[s],wx[deg/s],wy[deg/s],wz[deg/s],fx[m/s^2],fy[m/s^2],fz[m/s^2]"]
    lines += [f"{x:.3f},0.01,-0.02,0.03,0.1,-0.1,-9.8" for x in t]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_table_is_the_readers_options(tmp_path):
    """The table's keys reach the reader: the same file passes with gap_action = "warn"
    and fails with "fail"; with no table the reader's own defaults apply."""
    from mixnav.io.generic_csv import read_imu_csv
    f = _imu_csv(tmp_path / "imu.csv", gap=True)
    table = SimpleNamespace(format="csv", file="imu.csv", max_gap=0.5, gap_action="warn", spike_action="fail")
    with pytest.warns(UserWarning):
        imu = read_table("imu", table, tmp_path, "imu")
    assert isinstance(imu, ImuData) and imu.gaps == 1
    ref = read_imu_csv(f)   # no max_gap: no gap check
    np.testing.assert_array_equal(imu.dtheta, ref.dtheta)
    assert get_reader("imu", "csv")(f).gaps == 0
    with pytest.raises(DataError):
        read_table("imu", SimpleNamespace(**{**vars(table), "gap_action": "fail"}), tmp_path, "imu")


def test_every_dataset_kind_has_a_pipeline():
    kinds = set(typing.get_args(dataset_schema.DatasetInfo.model_fields["kind"].annotation))
    keys = {pipelines.pipeline_key(SimpleNamespace(dataset=SimpleNamespace(kind=k), raw_gnss=None)) for k in kinds}
    keys.add(pipelines.pipeline_key(SimpleNamespace(dataset=SimpleNamespace(kind="ins-gnss"), raw_gnss=object())))
    assert keys == set(pipelines.PIPELINES)
    for name, p in pipelines.PIPELINES.items():
        for fn in ("load", "run", "tables", "metrics", "truth", "write"):
            assert callable(getattr(p, fn, None)), (name, fn)
    assert raw_gnss_schema and vehicle_schema   # the kinds' own schemas are importable


def test_every_shipped_dataset_finds_its_pipeline():
    from mixnav.config import list_datasets, load_dataset
    seen = set()
    for name in list_datasets():
        ds, _, _ = load_dataset(name)
        p = pipelines.pipeline(ds)
        seen.add(pipelines.pipeline_key(ds))
        assert p is pipelines.PIPELINES[pipelines.pipeline_key(ds)]
        expected = {"gnss-raw": "gnss_raw", "odometry-gnss": "odometry_gnss"}.get(
            ds.dataset.kind, "ins_rinex" if getattr(ds, "raw_gnss", None) is not None else "ins_fixes")
        assert p.__name__.rsplit(".", 1)[1] == expected
    assert {"ins-gnss", "gnss-raw", "odometry-gnss"} <= seen


def test_unknown_kind_names_the_key():
    with pytest.raises(ConfigError) as exc:
        pipelines.pipeline(SimpleNamespace(dataset=SimpleNamespace(kind="sonar-gnss"), raw_gnss=None))
    assert exc.value.key == "dataset.kind" and "odometry-gnss" in str(exc.value)


# ---------------------------------------------------------------------------
# a new dataset kind from outside mixnav: its pipeline object and schema, one call
# ---------------------------------------------------------------------------
def _toy_kind():
    """A toy dataset kind written here alone: files of one number a line; the one method
    ``running-mean`` is the mean of the numbers so far, scored against ``truth``."""
    import json
    from typing import Literal

    import pandas as pd
    from pydantic import BaseModel, ConfigDict

    class Info(BaseModel):
        model_config = ConfigDict(extra="forbid")
        name: str
        kind: Literal["toy-numbers"]
        description: str = ""
        data_dir: str = "."

    class Numbers(BaseModel):
        model_config = ConfigDict(extra="forbid")
        file: str
        truth: float

    class ToyDataset(BaseModel):
        model_config = ConfigDict(extra="forbid")
        dataset: Info
        numbers: Numbers

    def load(ds, source, folder):
        return np.loadtxt(folder / ds.numbers.file, ndmin=1)

    def run(ds, source, folder, values, seed=0):
        mean = np.cumsum(values) / np.arange(1, len(values) + 1)
        return SimpleNamespace(dataset=ds, source=source, results={"running-mean": mean}, values=values)

    def tables(out):
        m = out.results["running-mean"]
        return {"running-mean": pd.DataFrame({"time_s": np.arange(len(m), dtype=float), "value": m,
                                              "error": m - out.dataset.numbers.truth})}

    def metrics(out, tables):
        e = tables["running-mean"]["error"].to_numpy()
        return {"running-mean": {"n_epochs": len(e), "final": float(tables["running-mean"]["value"].iloc[-1]),
                                 "horizontal_rmse_m": float(np.sqrt(np.mean(e ** 2))),
                                 "horizontal_max_m": float(np.abs(e).max())}}

    def write(out_dir, out, config_text=None, overwrite=False, sweeps=()):
        from mixnav.io.outdir import staged_output
        t = tables(out)
        m = {"dataset": out.dataset.dataset.name, "duration_s": float(len(out.values) - 1), "read_time_s": 0.0,
             "filter_time_s": 1e-3, "real_time_factor": 1.0, "methods": metrics(out, t)}
        with staged_output(Path(out_dir), "process", overwrite, [out.source]) as folder:
            (folder.path / "metrics.json").write_text(json.dumps(m))
        return m

    module = SimpleNamespace(load=load, run=run, tables=tables, metrics=metrics, truth=lambda out: None, write=write)
    return module, ToyDataset


@pytest.fixture
def toy_kind(monkeypatch, tmp_path):
    """The toy kind registered on copies of the registries (undone after the test), and a
    dataset file of it with its data."""
    from mixnav.config import loader
    monkeypatch.setattr(pipelines, "PIPELINES", dict(pipelines.PIPELINES))
    monkeypatch.setattr(loader, "_DATASET_SCHEMAS", dict(loader._DATASET_SCHEMAS))
    values = np.array([3.0, 5.0, 4.0, 8.0])
    (tmp_path / "n.txt").write_text("".join(f"{v!r}\n" for v in values.tolist()))
    cfg = tmp_path / "toy.toml"
    cfg.write_text(f'[dataset]\nname = "toy"\nkind = "toy-numbers"\ndata_dir = "{tmp_path.as_posix()}"\n\n'
                   '[numbers]\nfile = "n.txt"\ntruth = 4.5\n')
    return (*_toy_kind(), cfg, values)


def test_a_new_dataset_kind_is_one_registration_from_outside(toy_kind, tmp_path):
    """A kind this module defines alone (pipeline object and schema) is refused before it is
    registered, and after register_pipeline runs through the public API and the CLI
    (``mixnav process``), its numbers those of the closed form: the running mean of the
    file's numbers and its error against the file's truth."""
    import json

    from typer.testing import CliRunner

    import mixnav
    from mixnav.cli import app
    module, schema, cfg, values = toy_kind
    with pytest.raises(ConfigError) as exc:
        mixnav.process_dataset(str(cfg))
    assert exc.value.key == "dataset.kind"
    pipelines.register_pipeline("toy-numbers", module, schema)
    res = mixnav.process_dataset(str(cfg))
    mean = np.array([3.0, 4.0, 4.0, 5.0])                   # 3, (3+5)/2, (3+5+4)/3, 20/4
    np.testing.assert_array_equal(res.solutions["running-mean"]["value"], mean)
    assert res.metrics.loc["running-mean", "final"] == values.mean() == 5.0
    assert res.metrics.loc["running-mean", "horizontal_max_m"] == 1.5
    out = tmp_path / "out"
    done = CliRunner().invoke(app, ["process", str(cfg), "--out", str(out)])
    assert done.exit_code == 0, done.output
    written = json.loads((out / "metrics.json").read_text())
    assert written["methods"]["running-mean"]["final"] == 5.0 and "running-mean" in done.output
    np.testing.assert_allclose(written["methods"]["running-mean"]["horizontal_rmse_m"],
                               np.sqrt(np.mean((mean - 4.5) ** 2)), rtol=1e-15)


def test_the_new_kinds_schema_names_the_key_and_registrations_are_checked(toy_kind):
    """The registered schema's errors name the file and the key, as the built-in schemas' do;
    a kind that has a pipeline or a schema already, and a pipeline missing a function, are
    refused when registered."""
    import mixnav
    module, schema, cfg, _ = toy_kind
    pipelines.register_pipeline("toy-numbers", module, schema)
    cfg.write_text(cfg.read_text().replace("truth = 4.5", "truth = 4.5\ntruht = 4.5"))
    with pytest.raises(ConfigError, match="unknown key") as exc:
        mixnav.process_dataset(str(cfg))
    assert exc.value.key == "numbers.truht" and exc.value.file == str(cfg)
    with pytest.raises(ValueError, match="'toy-numbers' has a pipeline already"):
        pipelines.register_pipeline("toy-numbers", module, schema)
    with pytest.raises(ValueError, match="'gnss-raw' has a pipeline already"):
        pipelines.register_pipeline("gnss-raw", module)
    from mixnav.config.loader import register_dataset_schema
    with pytest.raises(ValueError, match="'odometry-gnss' has a schema already"):
        register_dataset_schema("odometry-gnss", schema)
    partial = SimpleNamespace(**{k: v for k, v in vars(module).items() if k not in ("write", "truth")})
    with pytest.raises(TypeError, match="has no truth, write"):
        pipelines.register_pipeline("toy-other", partial, schema)
    assert "toy-other" not in pipelines.PIPELINES
