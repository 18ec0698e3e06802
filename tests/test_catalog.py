"""Estimators by name: the catalogue line is all a new estimator needs to be usable
from a scenario file; its options are its keyword arguments, checked by it and
reported with the file's keys."""

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.errors import ArgumentError, ConfigError
from mixnav.experiment import methods
from mixnav.experiment.run import run_scenario
from mixnav.filters import catalog
from mixnav.filters.ekf import ErrorStateEkf
from mixnav.filters.sage_husa import SageHusaEkf

BASE = load_scenario("loose-demo")[2]


def _scenario(tmp_path, method_lines):
    text = BASE[:BASE.index("[[methods]]")] + "[[methods]]\nname = \"m\"\ntype = \"loose-ekf\"\n" + method_lines
    p = tmp_path / "sc.toml"
    p.write_text(text)
    return load_scenario(str(p))


def _build(sc, src):
    from mixnav.sim.scenario import simulate
    sim = simulate(sc, 1, src)
    return methods.build(sc.methods[0], sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0), sim


def test_an_estimator_with_options_is_built_from_the_file(tmp_path):
    sc, src, _ = _scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfading = 0.95\n')
    (filt, meas), sim = _build(sc, src)
    assert type(filt) is SageHusaEkf and filt.fading == 0.95
    direct = SageHusaEkf(filt.layout, sim.imu_model, fading=0.95).run(sim.imu, sim.init, meas)
    via_file = run_scenario(sc, src, seed=1).results["m"]
    np.testing.assert_array_equal(via_file.nav, direct.nav)


def test_bad_options_name_their_key(tmp_path):
    sc, src, _ = _scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfadding = 0.95\n')
    with pytest.raises(ConfigError, match="no option 'fadding'.*fading, scale0") as e:
        _build(sc, src)
    assert e.value.key == "methods[0].options.fadding" and e.value.file == src
    sc, src, _ = _scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfading = 1.5\n')
    with pytest.raises(ConfigError, match=r"\(0, 1\)") as e:  # the estimator's own check, in the file's words
        _build(sc, src)
    assert e.value.key == "methods[0].options.fading"


def test_an_unknown_estimator_is_a_config_error_listing_the_known_ones(tmp_path):
    with pytest.raises(ConfigError, match="unknown estimator 'kalman'.*sage-husa") as e:
        _scenario(tmp_path, 'estimator = "kalman"\n')
    assert e.value.key == "methods[0].estimator"


class _Halving(ErrorStateEkf):
    """A stand-in for a user's new estimator: the EKF with its absurd gate as an option."""

    def __init__(self, layout, imu_model, gate: float = 1e4, covariance_interval=1.0, clock=None):
        if gate <= 0:
            raise ArgumentError("must be positive", argument="gate")
        super().__init__(layout, imu_model, covariance_interval, gate, clock)


def test_one_catalogue_line_registers_a_new_estimator(tmp_path, monkeypatch):
    monkeypatch.setitem(catalog.ESTIMATORS, "halving", (f"{__name__}:_Halving", "test estimator"))
    sc, src, _ = _scenario(tmp_path, 'estimator = "halving"\n[methods.options]\ngate = 7.0\n')
    (filt, _), _ = _build(sc, src)
    assert type(filt) is _Halving and filt.absurd_sigma == 7.0
    sc, src, _ = _scenario(tmp_path, 'estimator = "halving"\n[methods.options]\ngate = -1.0\n')
    with pytest.raises(ConfigError) as e:
        _build(sc, src)
    assert e.value.key == "methods[0].options.gate"


def test_the_catalogue_imports_nothing_until_asked():
    import subprocess
    import sys
    code = ("import sys, mixnav.filters.catalog as c; assert 'sage-husa' in c.ESTIMATORS; "
            "print(any(m.startswith('mixnav.filters.sage_husa') or m == 'numba' for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"
