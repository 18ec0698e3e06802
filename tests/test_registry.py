"""The estimator registry (mixnav.filters.registry): every estimator registers itself in its
own module; the config's lists and options come from it; another installed package adds an
estimator through the entry-point group ``mixnav.estimators`` without editing mixnav."""

import importlib.metadata
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mixnav.config import load_dataset, load_scenario
from mixnav.errors import ArgumentError, ConfigError
from mixnav.filters import registry

from .conftest import data_file

ROOT = Path(__file__).resolve().parents[1]
BASE = load_scenario("loose-demo")[2]
RAW = (ROOT / "src/mixnav/config/datasets/android-static-filters.toml").read_text()
LOG = "pseudoranges_log_2016_06_30_21_26_07.txt"

#: the estimators the strapdown INS alone runs today (the ensemble filters need its batch
#: mechanization; the IMM and its em-bias mode are INS-only)
#: the IMM's modes and the EM bias estimator work on the strapdown INS only; the ensemble
#: filters (UKF, VB-AUKF, PF, DD2, GMPF) run on every motion model through the motion seam
STRAPDOWN_ONLY = {"imm", "em-bias"}


def _scenario(tmp_path, method_lines, name="sc.toml"):
    text = BASE[:BASE.index("[[methods]]")] + "[[methods]]\nname = \"m\"\ntype = \"loose-ekf\"\n" + method_lines
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _raw(tmp_path, block, name="raw.toml"):
    p = tmp_path / name
    p.write_text(RAW[:RAW.index("[[methods]]")] + block)
    return str(p)


def test_listing_the_names_imports_no_estimator():
    code = ("import sys; from mixnav.filters.registry import estimator_names as n; names = n(); "
            "assert {'ekf', 'sage-husa', 'pf', 'gmpf', 'imm'} <= set(names) and 'em-bias' not in names, names; "
            "print(any(m.startswith(('mixnav.filters.sage_husa', 'mixnav.filters.ekf', 'mixnav.engine')) "
            "or m == 'numba' for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("name", list(registry.builtin_modules()))
def test_each_builtin_registers_itself_in_its_own_module(name):
    spec = registry.estimator_spec(name)
    module = registry.builtin_modules()[name]
    assert spec.name == name and spec.cls.__module__ == module
    # the options live beside the estimator (its own module, or its light sibling <module>_options;
    # the shared gate base excepted), never in the config
    assert spec.options.__module__ in (module, f"{module}_options", "mixnav.filters.registry")
    assert not spec.options.__module__.startswith("mixnav.config")
    assert spec.description and "\n" not in spec.description
    # the motion models each ran on before the registry
    expected = ("strapdown",) if name in STRAPDOWN_ONLY else registry.MOTIONS
    assert spec.motions == expected
    assert spec.standalone is (name != "em-bias")


def test_options_models_forbid_unknown_keys_and_keep_the_defaults_of_the_estimators():
    import inspect

    from mixnav.filters.particle import ParticleEstimator
    from mixnav.filters.ukf import UnscentedEstimator
    for name, cls in (("pf", ParticleEstimator), ("ukf", UnscentedEstimator)):
        model = registry.estimator_spec(name).options
        for field, info in model.model_fields.items():
            p = inspect.signature(cls).parameters[field]
            assert info.default == p.default, (name, field)
        with pytest.raises(ArgumentError, match=f"no option 'nope'.*{next(iter(model.model_fields))}") as e:
            registry.estimator_spec(name).parse_options({"nope": 1})
        assert e.value.argument == "nope"


def test_the_generic_filter_is_the_estimator_on_the_engine(tmp_path):
    """``Filter('sage-husa', ...)`` (and the kept name SageHusaEkf) runs exactly what the engine
    runs with the estimator built by hand: the facade adds nothing."""
    from mixnav.engine import Engine
    from mixnav.filters.facade import Filter
    from mixnav.filters.sage_husa import SageHusaEkf, SageHusaEstimator
    from mixnav.measurements.loose import LooseGnss
    from mixnav.sim.scenario import simulate
    sc, src, _ = load_scenario(_scenario(tmp_path, 'estimator = "sage-husa"\n'))
    sim = simulate(sc, 1, src)
    f = Filter("sage-husa", _layout(), sim.imu_model, {"fading": 0.95})
    meas = [LooseGnss(sim.fixes, np.asarray(sc.gnss.lever_arm), f.layout)]
    a = f.run(sim.imu, sim.init, meas)
    b = SageHusaEkf(f.layout, sim.imu_model, fading=0.95).run(sim.imu, sim.init, meas)
    c = Engine(f.motion, SageHusaEstimator(0.95), meas, 1.0).run(sim.imu, sim.init)
    np.testing.assert_array_equal(a.nav, b.nav)
    np.testing.assert_array_equal(a.nav, c.nav)
    assert not f.can_smooth is registry.estimator_spec("sage-husa").can_smooth is False


def _layout():
    from mixnav.ins.error_model import get_layout
    return get_layout(15)


# --- bad input -----------------------------------------------------------------------------------

def test_an_unknown_estimator_names_the_key_and_lists_the_registered(tmp_path):
    with pytest.raises(ConfigError, match="unknown estimator 'kalman'.*ekf.*gmpf.*sage-husa") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "kalman"\n'))
    assert e.value.key == "methods[0].estimator"
    with pytest.raises(ConfigError, match="unknown estimator 'kalman'") as e:
        load_dataset(_raw(tmp_path, '[[methods]]\nname = "a"\nestimator = "wls"\n\n'
                                    '[[methods]]\nname = "b"\nestimator = "kalman"\n'))
    assert e.value.key == "methods[1].estimator"


def test_an_unknown_or_bad_option_names_its_key(tmp_path):
    with pytest.raises(ConfigError, match="no option 'fadding'.*fading, scale0") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfadding = 0.95\n'))
    assert e.value.key == "methods[0].options.fadding"
    with pytest.raises(ConfigError, match="less than 1") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "sage-husa"\n[methods.options]\nfading = 1.5\n'))
    assert e.value.key == "methods[0].options.fading"
    with pytest.raises(ConfigError, match="own table") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "robust-adaptive"\n[methods.options]\nk0 = 2.0\n'))
    assert e.value.key == "methods[0].options"


@pytest.mark.parametrize("estimator", ["imm"])
def test_an_estimator_on_a_motion_model_it_does_not_support_says_so(tmp_path, estimator):
    with pytest.raises(ConfigError, match=f"'{estimator}' does not run on the constant-velocity motion "
                                          "model.*strapdown") as e:
        load_dataset(_raw(tmp_path, '[[methods]]\nname = "a"\nestimator = "wls"\n\n[[methods]]\nname = "b"\n'
                                    'estimator = "ekf"\n\n'
                                    f'[[methods]]\nname = "c"\nestimator = "{estimator}"\n'))
    assert e.value.key == "methods[2].estimator"


@pytest.mark.parametrize("estimator", ["pf", "ukf", "gmpf", "dd2", "vb-aukf", "student-t"])
def test_the_ensemble_and_student_t_are_accepted_on_every_motion_model(tmp_path, estimator):
    ds, _, _ = load_dataset(_raw(tmp_path, '[[methods]]\nname = "a"\nestimator = "wls"\n\n'
                                 f'[[methods]]\nname = "c"\nestimator = "{estimator}"\n'))
    assert ds.methods[1].estimator == estimator


def test_an_imm_mode_must_be_registered_as_one(tmp_path):
    lines = ('estimator = "imm"\n[methods.imm]\ntransition = [[0.9, 0.1], [0.1, 0.9]]\n'
             '[[methods.imm.modes]]\nname = "a"\nmeasurements = ["gnss"]\n'
             '[[methods.imm.modes]]\nname = "b"\nmeasurements = ["gnss"]\nestimator = "pf"\n')
    with pytest.raises(ConfigError, match="'pf' cannot be a mode of an IMM.*em-bias") as e:
        load_scenario(_scenario(tmp_path, lines))
    assert e.value.key.startswith("methods[0].imm.modes[1]")


def test_registration_checks_its_own_arguments(monkeypatch):
    monkeypatch.setattr(registry, "_SPECS", dict(registry._SPECS))
    from pydantic import BaseModel
    with pytest.raises(ArgumentError, match="unknown motion") as e:
        registry.register_estimator("x", options=registry.NoOptions, motions=("flying",), description="x")
    assert e.value.argument == "motions"
    with pytest.raises(ArgumentError, match="pydantic model"):
        registry.register_estimator("x", options=dict, description="x")

    class Other(BaseModel):
        pass
    registry.estimator_spec("ekf")
    with pytest.raises(ArgumentError, match="registered twice"):
        registry.register_estimator("ekf", options=Other, description="an impostor")(type("Imp", (), {}))


# --- another package's estimator, through the entry-point group ------------------------------------

PLUGIN = '''
    """A stand-in for another package's estimator: the EKF with its blunder gate as an option,
    written against the registry's contract only (cls(options, absurd_sigma))."""
    from pydantic import BaseModel, ConfigDict, Field

    from mixnav.filters.ekf import KalmanEstimator
    from mixnav.filters.registry import register_estimator


    class HalvingOptions(BaseModel):
        model_config = ConfigDict(extra="forbid")
        gate: float = Field(default=1e4, gt=0, description="blunder gate [predicted sigmas]")


    @register_estimator("halving", options=HalvingOptions,
                        motions=("strapdown", "dead-reckoning", "constant-velocity"),
                        description="test plug-in: the EKF, its gate an option")
    class HalvingEstimator(KalmanEstimator):
        def __init__(self, options: HalvingOptions, absurd_sigma: float):
            super().__init__(options.gate)
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """The module ``mixnav_test_plugin`` on sys.path and announced under ``mixnav.estimators``."""
    pkg = tmp_path / "site"
    pkg.mkdir()
    (pkg / "mixnav_test_plugin.py").write_text(textwrap.dedent(PLUGIN))
    monkeypatch.syspath_prepend(str(pkg))
    monkeypatch.setattr(registry, "_SPECS", dict(registry._SPECS))
    ep = importlib.metadata.EntryPoint(name="halving", value="mixnav_test_plugin:HalvingEstimator",
                                       group=registry.ENTRY_POINT_GROUP)
    real = importlib.metadata.entry_points

    def entry_points(**kw):
        return [ep] if kw.get("group") == registry.ENTRY_POINT_GROUP else real(**kw)
    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    yield
    sys.modules.pop("mixnav_test_plugin", None)


def test_a_plugin_is_listed_without_being_imported(plugin):
    assert "halving" in registry.estimator_names()
    assert "mixnav_test_plugin" not in sys.modules
    spec = registry.estimator_spec("halving")
    assert "mixnav_test_plugin" in sys.modules and spec.cls.__name__ == "HalvingEstimator"
    est = spec.make({"gate": 7.0})
    assert est.absurd_sigma == 7.0


def test_a_scenario_method_names_a_plugin_and_runs(plugin, tmp_path):
    """The plug-in's estimator from a scenario file, its option checked with its key; with gate
    g it is the EKF with absurd_sigma g, bitwise."""
    from mixnav.experiment.run import run_scenario
    with pytest.raises(ConfigError, match="greater than 0") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "halving"\n[methods.options]\ngate = -1.0\n'))
    assert e.value.key == "methods[0].options.gate"
    sc, src, _ = load_scenario(_scenario(tmp_path, 'estimator = "halving"\n[methods.options]\ngate = 3.0\n'))
    ek, src_e, _ = load_scenario(_scenario(tmp_path, 'estimator = "ekf"\n[methods.options]\nabsurd_sigma = 3.0\n',
                                           "ekf.toml"))
    a = run_scenario(sc, src, seed=1).results["m"]
    b = run_scenario(ek, src_e, seed=1).results["m"]
    np.testing.assert_array_equal(a.nav, b.nav)
    assert a.recoveries == b.recoveries


def test_a_raw_gnss_dataset_method_names_a_plugin_and_runs(plugin, tmp_path):
    """On the phone log's constant-velocity filter the plug-in (gate 1e4) is the EKF, bitwise."""
    from mixnav.experiment.spp_process import process_raw
    folder = data_file("android-static", LOG).parent
    ds, src, _ = load_dataset(_raw(tmp_path, '[[methods]]\nname = "spp"\nestimator = "wls"\n\n'
                                             '[[methods]]\nname = "h"\nestimator = "halving"\n\n'
                                             '[[methods]]\nname = "e"\nestimator = "ekf"\n'))
    po = process_raw(ds, src, folder)
    np.testing.assert_array_equal(po.results["h"].nav, po.results["e"].nav)
    assert len(po.results["h"].nav) > 100


def test_the_builtins_are_found_in_their_modules_without_a_list(tmp_path):
    """A new estimator is one module that calls register_estimator: the listing reads the
    package's source, so there is no list to edit, and nothing is imported to list it."""
    found = registry.builtin_modules()
    assert list(found)[0] == "ekf" and set(found) >= {"ekf", "robust-adaptive", "gaussian-mixture", "imm",
                                                        "sage-husa", "ukf", "vb-aukf", "vb-akf", "epoch-mixture",
                                                        "pf", "dd2", "gmpf", "em-bias", "student-t"}
    (tmp_path / "newfilter.py").write_text('"""x"""\n\n@register_estimator("new-one", options=NoOptions,\n'
                                           '                    description="d")\nclass New:\n    pass\n')
    (tmp_path / "notes.py").write_text('"""How to:\n    @register_estimator("in-a-docstring")\n"""\n'
                                       'register_estimator("called", options=X, description="d")(Y)\n')
    assert registry.find_registrations(tmp_path, "pkg") == {"called": "pkg.notes", "new-one": "pkg.newfilter"}
    # an IMM-only mode is read from its registration's own arguments, not from a list
    (tmp_path / "mode.py").write_text('@register_estimator("a-mode", options=X, imm_child=f(g(1)),\n'
                                      '                    standalone=False, description="(x)")\nclass M:\n    pass\n'
                                      '@register_estimator("after", options=X, description="standalone=False "\n'
                                      '                    "in another call\'s text is not this one\'s")\n'
                                      'class A:\n    pass\n')
    assert registry.find_imm_only(tmp_path, "pkg") == {"a-mode"}
    assert registry.builtin_imm_only() == {"em-bias"}
    assert "em-bias" not in registry.estimator_names() and "em-bias" in registry.estimator_names(False)
    with pytest.raises(ArgumentError, match="unknown estimator 'not-yet'"):
        registry.estimator_spec("not-yet")


# --- the estimator tables, validated by the models their estimators registered ----------------------

def test_a_table_is_validated_by_its_owners_registered_model(tmp_path):
    """[robust] is robust-adaptive's RobustOptions, so its absurd_sigma is now readable from the
    file and reaches the estimator; the robust SPP (wls), which has neither prediction nor gate,
    refuses it and c, naming them; a table on an estimator it does not belong to names its owner."""
    from mixnav.experiment.methods import estimator_for
    from mixnav.filters.robust_adaptive import RobustOptions
    sc = load_scenario(_scenario(tmp_path, 'estimator = "robust-adaptive"\n[methods.robust]\nk0 = 2.0\n'
                                           'absurd_sigma = 50.0\n'))[0]
    assert isinstance(sc.methods[0].robust, RobustOptions) and sc.methods[0].robust.k0 == 2.0
    est = estimator_for(sc.methods[0], "sc.toml", 0)
    assert (est.k0, est.absurd_sigma) == (2.0, 50.0)
    for key in ("c", "absurd_sigma"):
        with pytest.raises(ConfigError, match=f"robust.{key}: the robust SPP has no prediction") as e:
            load_dataset(_raw(tmp_path, f'[[methods]]\nname = "a"\nestimator = "wls"\n[methods.robust]\n{key} = 3.0\n'))
        assert e.value.key == "methods[0]"
    with pytest.raises(ConfigError, match=r'a \[robust\] table needs estimator = "robust-adaptive"') as e:
        load_scenario(_scenario(tmp_path, '[methods.robust]\nk0 = 2.0\n'))
    assert e.value.key == "methods[0]"
    with pytest.raises(ConfigError, match=r'estimator = "imm" and an \[imm\] table go together') as e:
        load_scenario(_scenario(tmp_path, 'estimator = "imm"\n'))
    assert e.value.key == "methods[0]"


def test_the_training_stretch_is_what_each_estimator_says_it_needs(tmp_path, monkeypatch):
    """One simulated training draw serves every learner: a method's offline mixture learner and
    an IMM's mixture mode both ask (registry.training_needs through their options), the draw
    takes the union of kinds, the largest sample count and whether any learns the process
    noise; an online-only learner and a plain method ask for nothing."""
    import mixnav.sim.training as training
    from mixnav.experiment.run import _training
    methods = ('estimator = "gaussian-mixture"\n[methods.mixture.learn]\nmethod = "vb"\n'
               'observables = ["velocity"]\ntraining_samples = 700\nprocess = false\n\n'
               '[[methods]]\nname = "i"\ntype = "loose-ekf"\nestimator = "imm"\n[methods.imm]\n'
               'transition = [[0.9, 0.1], [0.1, 0.9]]\n'
               '[[methods.imm.modes]]\nname = "a"\nmeasurements = ["gnss"]\n'
               '[[methods.imm.modes]]\nname = "b"\nmeasurements = ["gnss"]\nestimator = "gaussian-mixture"\n'
               '[methods.imm.modes.mixture.learn]\nmethod = "vb"\nobservables = ["position"]\n'
               'training_samples = 500\n\n'
               '[[methods]]\nname = "o"\ntype = "loose-ekf"\nestimator = "gaussian-mixture"\n'
               '[methods.mixture.learn]\nmethod = "vb"\noffline = false\nobservables = ["position"]\n'
               '[methods.mixture.learn.online]\nwindow = 60\n')
    sc = load_scenario(_scenario(tmp_path, methods))[0]
    asked = []
    monkeypatch.setattr(training, "training_residuals", lambda sc, seed, kinds, n, process, source:
                        asked.append((kinds, n, process)) or {})
    assert _training(sc, 0, "sc.toml") == {}
    assert asked == [(["position", "velocity"], 700, True)]   # the mode learns its process noise (default)
    assert [need.residuals for need in registry.training_needs(sc.methods[1])] == [(("position",), 500, True)]
    assert registry.training_needs(sc.methods[2]) == []
    assert _training(load_scenario(_scenario(tmp_path, 'estimator = "ekf"\n'))[0], 0, "sc.toml") is None
