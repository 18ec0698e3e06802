"""An IMM mode is any registered estimator with an ``imm_child`` hook (mixnav.filters.registry):
one registered here, in this test module alone (no edit to mixnav), is read from a scenario
file as a mode, built through its hook with the mode's [options], and runs; an estimator
without the hook is refused naming ``methods[i].imm.modes[k].estimator``."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import BaseModel, ConfigDict, Field

from mixnav.config import load_scenario
from mixnav.errors import ArgumentError, ConfigError
from mixnav.filters import registry
from mixnav.filters.ekf import KalmanEstimator

BASE = load_scenario("loose-demo")[2]


class LabelledOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")

    label: str = Field(default="", description="a tag the child carries (shows the mode's options reached it)")


class LabelledKalman(KalmanEstimator):
    """The plain EKF under another name, remembering the label of each child built."""

    built: list = []

    def __init__(self, label: str, absurd_sigma: float, carry_mean: bool):
        super().__init__(absurd_sigma, carry_mean)
        LabelledKalman.built.append(label)


@pytest.fixture
def plug_ins(monkeypatch):
    """'test-labelled': a mode (its hook makes mean-carrying LabelledKalman children);
    'test-no-mode': registered, but without the hook. The built-ins are loaded first: the
    registrations are undone on a copy of the registry's table."""
    for name in registry.estimator_names(standalone_only=False):
        registry.estimator_spec(name)
    monkeypatch.setattr(registry, "_SPECS", dict(registry._SPECS))
    monkeypatch.setattr(LabelledKalman, "built", [])
    registry.register_estimator(
        "test-labelled", options=LabelledOptions, motions=("strapdown",), standalone=False,
        description="test plug-in: an IMM mode",
        imm_child=lambda o, absurd_sigma, context: lambda: LabelledKalman(o.label, absurd_sigma, True))(LabelledKalman)
    registry.register_estimator("test-no-mode", options=LabelledOptions, motions=("strapdown",),
                                description="test plug-in: not a mode")(LabelledKalman)


def _scenario(tmp_path, second_mode: str):
    text = BASE[:BASE.index("[[methods]]")] + f'''
[[methods]]
name = "ekf"
type = "loose-ekf"

[[methods]]
name = "imm"
type = "loose-ekf"
estimator = "imm"
[methods.imm]
transition = [[0.9, 0.1], [0.3, 0.7]]
initial_probabilities = [0.3, 0.7]
[[methods.imm.modes]]
name = "plain"
measurements = ["gnss"]
[[methods.imm.modes]]
name = "labelled"
measurements = ["gnss"]
{second_mode}
'''
    p = tmp_path / "imm_plugin.toml"
    p.write_text(text)
    return str(p)


def test_a_mode_registered_outside_mixnav_is_read_built_and_run(tmp_path, plug_ins):
    """The plug-in mode is the EKF: an IMM of it and an "ekf" mode on the same rows is the EKF
    whatever the transition matrix (mixing identical Gaussians gives them back), to 1e-9 as the
    in-library case of test_imm; its children carry the label of the file's [options]."""
    from mixnav.api import run_scenario
    path = _scenario(tmp_path, 'estimator = "test-labelled"\noptions = { label = "from the file" }')
    sc, _, _ = load_scenario(path)
    assert sc.methods[1].imm.modes[1].options == {"label": "from the file"}
    r = run_scenario(path, seed=2)
    assert LabelledKalman.built and set(LabelledKalman.built) == {"from the file"}
    imm, ekf = r.results["imm"], r.results["ekf"]
    np.testing.assert_allclose(imm.nav, ekf.nav, rtol=0, atol=1e-9)
    np.testing.assert_allclose(imm.sigma, ekf.sigma, rtol=1e-9)
    p = r.solutions["imm"][["p_mode_plain", "p_mode_labelled"]].to_numpy()
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-12)


def test_an_estimator_without_the_hook_is_refused_naming_the_mode(tmp_path, plug_ins):
    with pytest.raises(ConfigError, match=r"'test-no-mode' cannot be a mode of an IMM \(these can: .*"
                                          r"gaussian-mixture.*test-labelled") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "test-no-mode"'))
    assert e.value.key == "methods[1].imm.modes[1].estimator"
    # and the hook is asked for at build time too, for a spec a file never named
    with pytest.raises(ArgumentError, match="'test-no-mode' cannot be a mode") as e:
        registry.estimator_spec("test-no-mode").mode_factory()
    assert e.value.argument == "estimator"


def test_a_modes_options_are_checked_against_its_model(tmp_path, plug_ins):
    with pytest.raises(ConfigError, match="has no option 'lable'") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "test-labelled"\noptions = { lable = "x" }'))
    assert e.value.key == "methods[1].imm.modes[1].options.lable"
    # an estimator whose settings are a table of its own takes no [options], as a method
    with pytest.raises(ConfigError, match=r"takes its settings from its own table \(\[robust\]\)") as e:
        load_scenario(_scenario(tmp_path, 'estimator = "robust-adaptive"\noptions = { k0 = 2.0 }'))
    assert e.value.key.startswith("methods[1].imm.modes[1]")


def test_a_mode_needs_its_hook_to_register(monkeypatch):
    monkeypatch.setattr(registry, "_SPECS", dict(registry._SPECS))
    with pytest.raises(ArgumentError, match="no imm_child hook") as e:
        registry.register_estimator("test-half-mode", options=LabelledOptions, imm_mode=True,
                                    description="x")(LabelledKalman)
    assert e.value.argument == "imm_child"
