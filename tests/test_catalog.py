"""Estimators by name (the registry, mixnav.filters.registry): a registration is all a new estimator needs to be usable from a scenario file;
its options are checked by its options model and reported with the file's keys."""

import numpy as np
import pytest

from mixnav.config import load_scenario
from mixnav.errors import ConfigError
from mixnav.experiment import methods
from mixnav.experiment.run import run_scenario
from mixnav.filters import registry
from mixnav.filters.facade import Filter
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
    assert type(filt) is Filter and filt.name == "sage-husa" and filt.options.fading == 0.95
    direct = SageHusaEkf(filt.layout, sim.imu_model, fading=0.95).run(sim.imu, sim.init, meas)
    via_file = run_scenario(sc, src, seed=1).results["m"]
    np.testing.assert_array_equal(via_file.nav, direct.nav)


def test_bad_options_name_their_key(tmp_path):
    with pytest.raises(ConfigError, match="no option 'fadding'.*fading, scale0") as e:
        _scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfadding = 0.95\n')
    assert e.value.key == "methods[0].options.fadding"
    with pytest.raises(ConfigError, match="less than 1") as e:  # the options model's check, in the file's words
        _scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfading = 1.5\n')
    assert e.value.key == "methods[0].options.fading"


def test_an_unknown_estimator_is_a_config_error_listing_the_known_ones(tmp_path):
    with pytest.raises(ConfigError, match="unknown estimator 'kalman'.*sage-husa") as e:
        _scenario(tmp_path, 'estimator = "kalman"\n')
    assert e.value.key == "methods[0].estimator"


def test_every_listed_name_has_a_registration_and_the_imm_modes_are_apart():
    names = registry.estimator_names()
    assert all(registry.estimator_spec(n).name == n for n in names)
    assert "em-bias" not in names and "em-bias" in registry.estimator_names(standalone_only=False)


def test_listing_imports_no_estimator_until_asked():
    import subprocess
    import sys
    code = ("import sys, mixnav.filters.registry as r; assert 'sage-husa' in r.estimator_names(); "
            "print(any(m.startswith('mixnav.filters.sage_husa') or m == 'numba' for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"
