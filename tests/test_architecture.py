"""The import structure ARCHITECTURE.md draws: floors, no upward import, no cycle.

Every import counts, the ones inside functions too (a lazy import is still a
dependency). A package's floor is in FLOORS; a module may import its own floor
or any floor below, never one above.
"""

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "mixnav"

#: floor of each top-level module or package of mixnav (ARCHITECTURE.md, "Floors")
FLOORS = {
    "errors": 0, "units": 0, "linalg": 0, "_version": 0,
    "names": 0,  # safe_name: the file-name rule of the config's method names and the output folders
    "markov": 0,  # check_transition: the IMM's transition matrix, checked by the filter and the config
    "_jit": 0,  # serial_and_parallel: the kernels' twin factory (numba only)
    "formats": 0,  # the readers' formats, read from io's source: the config checks format keys without io
    "attitude": 1, "geodesy": 1, "data": 2,
    "ins": 3, "motion": 3, "gnss": 3, "noise": 3, "io": 3, "alignment": 4,
    "measurements": 4,
    "engine": 5,
    "filters": 6,
    "config": 7,
    "sim": 8,  # simulate(scenario): a scenario file's run; its parts (trajectory, gnss, rng) take plain arguments
    "experiment": 9,
    "api": 10, "cli": 10, "__init__": 10, "__main__": 10,
}
#: the engine's status codes sit below the kernels that return them
MODULE_FLOORS = {"mixnav.engine.status": 0}


def _module_name(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path):
    """Absolute names of the mixnav modules ``path`` imports (at any depth of the code)."""
    mod = _module_name(path)
    pkg = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("mixnav"):
                    yield a.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.startswith("mixnav"):
                for a in node.names:  # "from .x import y" may import the module x.y
                    sub = f"{target}.{a.name}"
                    yield (sub if _exists(sub) else target), node.lineno


def _exists(name: str) -> bool:
    p = SRC.parent.joinpath(*name.split("."))
    return p.with_suffix(".py").exists() or (p / "__init__.py").exists()


def _floor(module: str) -> int:
    if module in MODULE_FLOORS:
        return MODULE_FLOORS[module]
    parts = module.split(".")
    top = parts[1] if len(parts) > 1 else "__init__"
    return FLOORS[top]


def _graph():
    edges = {}
    for path in sorted(SRC.rglob("*.py")):
        mod = _module_name(path)
        edges[mod] = [(t, line) for t, line in _imports(path) if t != mod]
    return edges


def test_every_package_has_a_floor():
    missing = sorted({m.split(".")[1] for m in _graph() if "." in m and m.split(".")[1] not in FLOORS})
    assert not missing, f"add these to FLOORS (and to ARCHITECTURE.md): {missing}"


def test_no_module_imports_a_higher_floor():
    bad = []
    for mod, targets in _graph().items():
        for t, line in targets:   # the root package too: it re-exports the top floor (api)
            if _floor(t) > _floor(mod):
                bad.append(f"{mod}:{line} imports {t} (floor {_floor(mod)} -> {_floor(t)})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_no_import_cycles():
    # a package's __init__ that re-exports its modules is not a cycle with them
    # when the modules import siblings directly; cycles are searched among modules.
    def own(u, v):   # a package and its own submodules
        return v.startswith(u + ".") or u.startswith(v + ".") and _is_package(v)

    g = {m: {t for t, _ in ts if t != "mixnav" and not own(m, t)} for m, ts in _graph().items()}
    cycles = _cycles(g)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def _top(module: str) -> str:
    """The top-level package or module of ``module`` ("__init__" for the root package)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _package_graph():
    """Top-level packages and modules, an arrow where any module of one imports one of the other."""
    g = {}
    for mod, targets in _graph().items():
        for t, _ in targets:
            if _top(t) != _top(mod):
                g.setdefault(_top(mod), set()).add(_top(t))
    return g


def _cycles(g):
    """Cycles of the graph ``g`` (node -> set of nodes), found by depth-first search: at
    least one per strongly connected loop, as the path that closes it."""
    state, stack, cycles = {}, [], []

    def visit(u):
        state[u] = 1
        stack.append(u)
        for v in sorted(g.get(u, ())):
            if state.get(v) == 1:
                cycles.append(stack[stack.index(v):] + [v])
            elif not state.get(v):
                visit(v)
        stack.pop()
        state[u] = 2

    for u in sorted(g):
        if not state.get(u):
            visit(u)
    return cycles


def test_no_cycles_between_packages():
    """Modules may each be acyclic while their packages form a loop (noise -> io -> gnss
    -> noise was one): packages are checked as wholes, the root package among them."""
    cycles = _cycles(_package_graph())
    assert not cycles, "package cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_the_package_cycle_check_sees_a_loop():
    assert _cycles({"noise": {"io"}, "io": {"gnss"}, "gnss": {"noise"}, "data": set()}) == \
        [["gnss", "noise", "io", "gnss"]]
    assert not _cycles({"noise": {"io"}, "io": {"gnss"}, "gnss": set()})


def _is_package(name: str) -> bool:
    return (SRC.parent.joinpath(*name.split(".")) / "__init__.py").exists()


@pytest.mark.parametrize("probe", ["mixnav.filters.ekf", "mixnav.engine.engine"])
def test_the_graph_reader_sees_imports(probe):
    """The test reads real edges (so an empty graph cannot pass it)."""
    g = _graph()
    assert probe in g and len(g[probe]) >= 3


#: the ensemble estimators reach the strapdown kernels only through the motion model's
#: seam (engine/protocols.py MotionModel: member_states, propagate_members, ...), so they run
#: on every motion model; the particle filter's fused strapdown step is the strapdown
#: motion's too (StrapdownMotion.particle_kernels, ins/_particle_kernels.py), its fused loose
#: update the loose model's (member_update: test_no_filter_knows_a_concrete_measurement_model).
ENSEMBLE_MODULES = ("mixnav.filters.ukf", "mixnav.filters.dd2", "mixnav.filters.gmpf",
                    "mixnav.filters._ukf_kernels", "mixnav.filters.particle", "mixnav.filters._pf_kernels")


@pytest.mark.parametrize("module", ENSEMBLE_MODULES)
def test_ensemble_filters_import_no_strapdown_kernels(module):
    path = SRC.joinpath(*module.split(".")[1:]).with_suffix(".py")
    bad = [f"{module}:{line} imports {t}" for t, line in _imports(path)
           if t.startswith("mixnav.ins._") or t == "mixnav.ins._kernels"]
    assert not bad, "\n".join(bad)


def _config_reaches_beyond(graph) -> list[str]:
    """Imports of a ``mixnav.config`` module into ``filters`` other than the registry and the
    settings models' unit fields (option_fields: no estimator in it), or into ``io``."""
    return [f"{mod}:{line} imports {t}" for mod, targets in graph.items()
            if mod == "mixnav.config" or mod.startswith("mixnav.config.")
            for t, line in targets
            if (_top(t) == "filters" and t not in ("mixnav.filters.registry", "mixnav.filters.option_fields"))
            or _top(t) == "io"]


def test_config_imports_only_the_registry_from_filters_and_nothing_from_io():
    """The config validates estimator names and options against the registry (and builds its
    unit fields on the one definition, filters.option_fields), and nothing else of the filters (checks both need live below both: mixnav.markov, mixnav.names)."""
    graph = _graph()
    config = [ts for mod, ts in graph.items() if mod.startswith("mixnav.config.")]
    assert any(t == "mixnav.filters.registry" for ts in config for t, _ in ts)  # its lazy imports are seen
    bad = _config_reaches_beyond(graph)
    assert not bad, "\n".join(bad)


def test_the_config_import_check_sees_a_forbidden_import():
    fake = {"mixnav.config.method_schema": [("mixnav.filters.imm", 7), ("mixnav.filters.registry", 8)],
            "mixnav.config.vehicle_schema": [("mixnav.io.outdir", 9)],
            "mixnav.experiment.run": [("mixnav.io.outdir", 3)]}
    assert _config_reaches_beyond(fake) == ["mixnav.config.method_schema:7 imports mixnav.filters.imm",
                                            "mixnav.config.vehicle_schema:9 imports mixnav.io.outdir"]


def _concrete_measurement_models() -> dict:
    """Every measurement-model class mixnav defines (a subclass of ``MeasurementModel``, the
    protocol itself left out), by name, found by importing each module of ``measurements``."""
    import importlib
    import pkgutil

    import mixnav.measurements as pkg
    from mixnav.measurements.base import MeasurementModel

    found = {}
    for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
        mod = importlib.import_module(info.name)
        for name, obj in vars(mod).items():
            if isinstance(obj, type) and issubclass(obj, MeasurementModel) and obj is not MeasurementModel:
                found[name] = obj
    return found


def _concrete_model_uses(source: str, module: str, concrete: dict) -> list[str]:
    """Where the code of ``module`` (its ``source``) imports a concrete measurement model from
    ``mixnav.measurements`` (at any depth of the code) or
    names one (an identifier or an attribute such as ``tight.TightGnss``; docstrings and
    strings are prose)."""
    import importlib

    pkg = module.rpartition(".")[0]
    bad = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            base = pkg.split(".")[:len(pkg.split(".")) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            if not target.startswith("mixnav.measurements"):
                continue
            for a in node.names:   # a module imported whole is seen where it is used (attributes)
                if not _exists(f"{target}.{a.name}") and getattr(importlib.import_module(target), a.name,
                                                                 None) in concrete.values():
                    bad.append(f"{module}:{node.lineno} imports {a.name} from {target}")
        elif isinstance(node, ast.Name) and node.id in concrete:
            bad.append(f"{module}:{node.lineno} names {node.id}")
        elif isinstance(node, ast.Attribute) and node.attr in concrete:
            bad.append(f"{module}:{node.lineno} names {node.attr}")
    return sorted(set(bad))


#: measurement models that wrap another model of any kind (allowed in filters/)
WRAPPERS = ("DifferencedMeasurement",)


def test_no_filter_knows_a_concrete_measurement_model():
    """An estimator sees a measurement model only through its protocol (measurements/base.py:
    rows, predict_batch, the optional member_update capability): no module of filters/ imports
    or names a concrete model class (the particle filter once tested type(epoch.model) is
    LooseGnss to pick its fused update; issue 33)."""
    concrete = _concrete_measurement_models()
    assert {"LooseGnss", "TightGnss", "PseudorangeGnss"} <= set(concrete)   # the search finds them
    # a combinator over any model, not a sensor's model: the coloured bank (M6, P2) differences
    # whatever measurements its method has, and builds that wrapping in its own module
    for wrapper in WRAPPERS:
        assert concrete.pop(wrapper, None) is not None, f"{wrapper} is no longer a measurement model"
    bad, paths = [], sorted((SRC / "filters").rglob("*.py"))
    assert len(paths) > 10
    for path in paths:
        bad += _concrete_model_uses(path.read_text(), _module_name(path), concrete)
    assert not bad, "\n".join(bad)


def test_the_concrete_model_check_sees_an_import_and_a_name():
    concrete = _concrete_measurement_models()
    src = ("from ..measurements.kinds import POSITION\n"
           "def f(epoch):\n"
           "    from ..measurements.loose import LooseGnss, antenna_lla\n"
           "    from ..measurements import tight\n"
           "    return type(epoch.model) is LooseGnss or isinstance(epoch.model, tight.TightGnss)\n")
    assert _concrete_model_uses(src, "mixnav.filters.fake", concrete) == [
        "mixnav.filters.fake:3 imports LooseGnss from mixnav.measurements.loose",
        "mixnav.filters.fake:5 names LooseGnss",
        "mixnav.filters.fake:5 names TightGnss"]
