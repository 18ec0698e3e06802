"""The reader registry and the pipeline dispatch table: every kind the dataset schemas accept
has a pipeline, the registered formats are the ones the schemas and the docs list, and a
reader is chosen (and given its options) by the table's format."""

import re
import typing
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mixnav.config import dataset_schema, raw_gnss_schema, vehicle_schema
from mixnav.data import ImuData, RawPseudoranges
from mixnav.errors import ConfigError, DataError
from mixnav.experiment import pipelines
from mixnav.io import registry
from mixnav.io.readers import KIND_TYPES, formats, get_reader, read_table

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _literal(model, field="format") -> set:
    return set(typing.get_args(model.model_fields[field].annotation))


#: what each reader kind serves in the dataset schemas
SCHEMA_FORMATS = {
    "imu": _literal(dataset_schema.ImuFile),
    "gnss-fixes": _literal(dataset_schema.GnssFile),
    # every raw-GNSS reader, smartLoc's corrected pseudoranges (the odometry datasets' too) included
    "raw-gnss": (_literal(dataset_schema.RawGnss) | _literal(dataset_schema.InsRawGnss)
                 | _literal(vehicle_schema.Pseudoranges)),
    "odometry": _literal(vehicle_schema.OdometryFile),
    "reference": _literal(dataset_schema.ReferenceFile) | _literal(vehicle_schema.VehicleReference)
    | _literal(raw_gnss_schema.RawReference),
}


def test_registered_formats_are_the_schemas_formats():
    assert set(KIND_TYPES) == set(SCHEMA_FORMATS)
    for kind, listed in SCHEMA_FORMATS.items():
        assert set(formats(kind)) == listed, kind


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
    monkeypatch.setattr(registry, "_READERS", dict(registry._READERS))
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
