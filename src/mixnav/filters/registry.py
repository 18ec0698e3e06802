"""The estimator registry: every estimator a scenario or dataset file can name.

An estimator registers itself, in its own module, with everything the rest of
mixnav needs to know about it::

    from .registry import register_estimator

    class StudentTOptions(pydantic.BaseModel):       # model_config = ConfigDict(extra="forbid")
        dof: float = Field(5.0, gt=2, description="degrees of freedom")

    @register_estimator("student-t", options=StudentTOptions,
                        motions=("strapdown", "dead-reckoning", "constant-velocity"),
                        description="Student-t filter with variational-Bayes noise")
    class StudentTEstimator:                         # the engine's Estimator protocol
        def __init__(self, options: StudentTOptions, absurd_sigma: float): ...

Keywords of :func:`register_estimator`:

``options``
    ONE pydantic model of the estimator's settings (``[methods.options]`` of a file),
    ``extra="forbid"``, units in the field descriptions where they apply.
``motions``
    The motion models it runs on: names of :data:`MOTIONS`.
``description``
    One line (listed by ``mixnav scenarios``).
``measurements``
    The measurement method types it is restricted to (None: every one).
``can_smooth``
    Whether the RTS smoother applies to its results (one Gaussian per event).
``build``
    None: the estimator is built as ``cls(options, absurd_sigma)``. Otherwise a
    callable ``build(options, absurd_sigma, context)`` for an estimator that needs more
    than its options (a :class:`BuildContext`: the motion model, the method entry,
    training data, ...).
``table``
    Where a file gives its settings when not in ``[methods.options]`` (``"robust"``,
    ``"mixture"``, ``"imm"``, ``"em"``: a table of the method, or of an IMM mode, named so);
    ``options`` is then the model of that table, and the config validates the table with
    it (:func:`validate_table`). A table whose model has required keys must be given
    (``estimator = "imm"`` needs ``[imm]``).
``build_filter``
    For an estimator whose filter on the strapdown INS is more than ``Filter(name, ...)``
    (settings learned once per method, measurement models of its own, what callers read
    on the filter): ``build_filter(options, context) -> (filter, measurement models)``,
    called once per method with the method's models in ``context.measurements``.
``imm_child``
    What makes it a mode of an IMM: ``imm_child(options, absurd_sigma, context)`` returns
    a factory of fresh mean-carrying estimators (one per run; ``carry_mean=True``),
    ``context.mode`` the mode's entry and ``context.key`` its file key
    (``methods[i].imm.modes[k]``). ``imm_mode`` defaults to whether it is given.
``check``
    Optional ``check(options, measurements, mode)``: a ValueError when these settings
    cannot be used with these measurement names (a method's: ``"gnss"`` and its aiding; a
    mode's: those it lists; ``mode``: whether it is an IMM mode), checked as the file is read.
``keys``
    Argument names of its build's :class:`ArgumentError` -> the method's file keys where
    they differ (``{"k0": "robust.k0"}``).
``standalone``
    False for an estimator that is only a mode of an IMM (``em-bias``).

A variant of an estimator in another module (the coloured-noise bank, selected by the
``[mixture.colored]`` table of the bank's options) registers its own ``build_filter`` with
:func:`register_variant`; it is found like a registration, by reading the source, and
imported with the estimator.

Lookup is lazy: :func:`estimator_names` lists the built-in names from a small table
of name -> module (a module named there but absent is skipped: ``student-t`` is listed
there before its file lands, so that the file is the only edit) and the names of the
entry-point group ``mixnav.estimators``
(another installed package's estimators) without importing any of them; the
knowledge (options, motions, description) is in the estimator's module, imported by
:func:`estimator_spec` when a method names it. An entry point's value is a module or
an object in it (``"pkg.mod"`` or ``"pkg.mod:Class"``); loading it runs the
registration.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import import_module
from pathlib import Path
from typing import Any, Callable

from pydantic import BaseModel, ConfigDict, Field

from ..errors import ArgumentError

#: The default absurd-innovation gate [standard deviations]: an innovation this many
#: predicted standard deviations out is a blunder (a units or timing error, a wrong
#: satellite), not noise, and its epoch is rejected (``ABSURD``, counted). Every
#: estimator's ``absurd_sigma`` defaults to it.
ABSURD_SIGMA = 1e4

#: the motion models an estimator can declare (mixnav.ins.strapdown, mixnav.motion)
MOTIONS = ("strapdown", "dead-reckoning", "constant-velocity")

#: the entry-point group another package registers estimators under
ENTRY_POINT_GROUP = "mixnav.estimators"

#: the package whose modules hold the built-in estimators
BUILTIN_PACKAGE = "mixnav.filters"

#: a module-level registration, ``register_estimator("name", ...)`` or its decorator form
_REGISTRATION = re.compile(r'^@?register_estimator\(\s*"([^"]+)"', re.M)
#: a module-level variant registration, ``register_variant("name", ...)``
_VARIANT = re.compile(r'^register_variant\(\s*"([^"]+)"', re.M)


#: ``standalone=False`` among a registration's arguments (an IMM-only mode)
_NOT_STANDALONE = re.compile(r"\bstandalone\s*=\s*False\b")


#: a string literal on one line (the registrations' descriptions)
_STRING = re.compile(r""""(?:[^"\\\n]|\\.)*"|'(?:[^'\\\n]|\\.)*'""")


def _call_arguments(text: str, start: int) -> str:
    """The text of the call whose ``(`` is the first one at or after ``start``, up to its
    matching ``)``, with the insides of its string literals blanked (a description may
    hold parentheses or the words ``standalone=False``)."""
    text = _STRING.sub(lambda m: m.group(0)[0] + " " * (len(m.group(0)) - 2) + m.group(0)[-1], text)
    i = text.index("(", start)
    depth = 0
    for j in range(i, len(text)):
        depth += {"(": 1, ")": -1}.get(text[j], 0)
        if depth == 0:
            return text[i:j + 1]
    return text[i:]


def _scan(folder, package: str) -> dict[str, tuple[str, bool]]:
    """name -> (module, standalone) of every module-level registration in ``folder``'s source."""
    found = {}
    for path in sorted(Path(folder).glob("*.py")):
        text = path.read_text(encoding="utf-8")
        for m in _REGISTRATION.finditer(text):
            found.setdefault(m.group(1), (f"{package}.{path.stem}",
                                          not _NOT_STANDALONE.search(_call_arguments(text, m.start()))))
    return dict(sorted(found.items(), key=lambda item: (item[0] != "ekf", item[0])))


def find_registrations(folder, package: str) -> dict[str, str]:
    """Estimator name -> module, for every module of ``folder`` (the files of ``package``)
    that registers an estimator at module level, read from the source text: nothing is
    imported, so listing the estimators compiles no kernel. ``"ekf"`` (the default) first,
    then by name."""
    return {name: module for name, (module, _) in _scan(folder, package).items()}


def find_imm_only(folder, package: str) -> set[str]:
    """The names among :func:`find_registrations` registered with ``standalone=False``
    (a mode of an IMM only), read from the registration's own arguments."""
    return {name for name, (_, standalone) in _scan(folder, package).items() if not standalone}


@lru_cache(maxsize=1)
def variant_modules() -> dict[str, list[str]]:
    """Built-in estimator name -> the modules that register variants of it (read from the source)."""
    found: dict[str, list[str]] = {}
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        for name in _VARIANT.findall(path.read_text(encoding="utf-8")):
            found.setdefault(name, []).append(f"{BUILTIN_PACKAGE}.{path.stem}")
    return found


@lru_cache(maxsize=1)
def builtin_modules() -> dict[str, str]:
    """Built-in estimator name -> the module that registers it (imported only when named).
    A new estimator is one module of this package that calls :func:`register_estimator`:
    it is found here, with no list to edit."""
    return find_registrations(Path(__file__).resolve().parent, BUILTIN_PACKAGE)


@lru_cache(maxsize=1)
def builtin_imm_only() -> set[str]:
    """The built-in estimators that are only IMM modes (``standalone=False`` in their registration)."""
    return find_imm_only(Path(__file__).resolve().parent, BUILTIN_PACKAGE)


#: method types of a scenario's INS methods (``type = "..."``) -> one-line description
METHOD_TYPES = {
    "loose-ekf": "GNSS position/velocity (loose coupling)",
    "tight-ekf": "pseudorange + Doppler (tight coupling, 17 states)",
    "tdcp-ekf": "pseudorange + TDCP (P1 eqs. 1-4; stochastic cloning of the previous antenna position and clock)",
}


@dataclass
class BuildContext:
    """What an estimator's ``build`` may need beyond its options (all optional).

    ``motion``: the motion model of the run, ``motion_name`` its name (:data:`MOTIONS`);
    ``method``: the config's method entry; ``training``: training residuals (simulated
    scenarios); ``seed``; ``measurements``: the method's measurement models,
    ``named_measurements`` the same by the names a file uses (``"gnss"``, each aiding);
    ``source``, ``index``: the file and the method's index, ``key`` the file key of the
    entry being built (``methods[i]``, or ``methods[i].imm.modes[k]`` for a mode, whose
    entry is ``mode``): for errors; on the strapdown INS, ``layout``, ``imu_model``,
    ``covariance_interval`` and ``clock`` of the filter; ``extra``: anything a pipeline
    hands over (e.g. the epoch mixture's start from a track alignment)."""

    motion: Any = None
    method: Any = None
    training: Any = None
    seed: int = 0
    measurements: Any = None
    source: str | None = None
    index: int = 0
    extra: dict = field(default_factory=dict)
    motion_name: str | None = None
    named_measurements: dict = field(default_factory=dict)
    key: str | None = None
    mode: Any = None
    layout: Any = None
    imu_model: Any = None
    covariance_interval: float = 1.0
    clock: Any = None

    @property
    def entry_key(self) -> str:
        """``key``, or ``methods[index]`` when not set."""
        return self.key or f"methods[{self.index}]"


@dataclass(frozen=True)
class EstimatorSpec:
    """One registered estimator (see the module docstring)."""

    name: str
    cls: type
    options: type
    motions: tuple
    description: str
    measurements: tuple | None = None
    can_smooth: bool = True
    build: Callable | None = None
    table: str | None = None
    imm_mode: bool = False
    standalone: bool = True
    build_filter: Callable | None = None
    imm_child: Callable | None = None
    check: Callable | None = None
    keys: dict = field(default_factory=dict)

    def parse_options(self, values=None):
        """``values`` (a dict, or an instance of the options model) validated: an instance
        of ``self.options``; a bad one is an :class:`ArgumentError` naming the option."""
        if isinstance(values, self.options):
            return values
        return validate_options(self.options, dict(values or {}), self.name)

    def make(self, options=None, absurd_sigma: float = ABSURD_SIGMA, context: BuildContext | None = None):
        """A fresh estimator with ``options`` (dict or model instance) for one run."""
        opts = self.parse_options(options)
        if "absurd_sigma" in opts.model_fields_set:   # a file's options.absurd_sigma wins
            absurd_sigma = opts.absurd_sigma
        if self.build is None:
            return self.cls(opts, absurd_sigma)
        return self.build(opts, absurd_sigma, context or BuildContext())

    def mode_factory(self, options=None, context: BuildContext | None = None):
        """The factory of fresh mean-carrying estimators of this estimator as a mode of an IMM
        (its ``imm_child`` hook); an estimator without one: an :class:`ArgumentError`
        (argument ``estimator``) listing those that can be a mode."""
        if self.imm_child is None:
            raise ArgumentError(f"estimator '{self.name}' cannot be a mode of an IMM (these can: "
                                f"{', '.join(imm_mode_names())})", argument="estimator")
        opts = self.parse_options(options)
        absurd_sigma = opts.absurd_sigma if "absurd_sigma" in opts.model_fields_set else ABSURD_SIGMA
        return self.imm_child(opts, absurd_sigma, context or BuildContext())

    def default_options(self):
        """The options model with every default, or None when it has required keys (a table
        that must be given)."""
        from pydantic import ValidationError
        try:
            return self.options()
        except ValidationError:
            return None

    def runs_on(self, motion: str) -> bool:
        return motion in self.motions

    def filter_builder(self, options):
        """The ``build_filter`` for these ``options``: a registered variant's when its options key
        is set (:func:`register_variant`), else the estimator's own (None: ``Filter(name, ...)``)."""
        for key, build_filter in _VARIANTS.get(self.name, {}).items():
            if getattr(options, key, None) is not None:
                return build_filter
        return self.build_filter


class GateOptions(BaseModel):
    """The option every built-in estimator takes: its blunder gate."""

    model_config = ConfigDict(extra="forbid")

    absurd_sigma: float = Field(default=ABSURD_SIGMA, gt=0, description="innovations beyond this many predicted "
                                "standard deviations are rejected as blunders (counted)")


class NoOptions(BaseModel):
    """Settings of an estimator that takes them from its own table of the method, not [options]."""

    model_config = ConfigDict(extra="forbid")


def validate_options(model: type, values: dict, name: str):
    """``model(**values)``; a bad value or an unknown key is an :class:`ArgumentError` whose
    argument is the option (the config layer turns it into ``methods[i].options.<key>``)."""
    from pydantic import ValidationError
    try:
        return model.model_validate(values)
    except ValidationError as exc:
        err = exc.errors()[0]
        key = ".".join(map(str, err["loc"]))
        known = ", ".join(model.model_fields) or "none"
        if err["type"] == "extra_forbidden":
            raise ArgumentError(f"estimator '{name}' has no option '{key}' (its options: {known})",
                                argument=key) from None
        msg = err["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        raise ArgumentError(f"{msg} (options of '{name}': {known})", argument=key) from None


_SPECS: dict[str, EstimatorSpec] = {}
_VARIANTS: dict[str, dict[str, Callable]] = {}


def register_variant(estimator: str, *, key: str, build_filter: Callable) -> None:
    """Register a variant of ``estimator`` (at module level, in the variant's own module): when
    the estimator's options have ``key`` set (not None), its filter on the strapdown INS is
    ``build_filter(options, context)`` (as the registration's keyword) instead of the estimator's."""
    _VARIANTS.setdefault(estimator, {})[key] = build_filter


def register_estimator(name: str, *, options: type, motions=MOTIONS, description: str,
                       measurements=None, can_smooth: bool = True, build: Callable | None = None,
                       table: str | None = None, imm_mode: bool | None = None, standalone: bool = True,
                       build_filter: Callable | None = None, imm_child: Callable | None = None,
                       check: Callable | None = None, keys: dict | None = None):
    """Class decorator: register the estimator as ``name`` (module docstring). Returns the
    class unchanged; one class may be registered under several names (``ukf``, ``vb-aukf``)."""
    if imm_mode is None:
        imm_mode = imm_child is not None
    if imm_mode and imm_child is None:
        raise ArgumentError(f"estimator '{name}' is an IMM mode but gives no imm_child hook (the factory of "
                            "its mean-carrying estimator)", argument="imm_child")
    if not (isinstance(options, type) and issubclass(options, BaseModel)):
        raise ArgumentError(f"options of estimator '{name}' must be a pydantic model class, got {options!r}",
                            argument="options")
    motions = tuple(motions)
    bad = [m for m in motions if m not in MOTIONS]
    if bad or not motions:
        raise ArgumentError(f"estimator '{name}': unknown motion model(s) {bad} (known: {', '.join(MOTIONS)})",
                            argument="motions")
    if not description or "\n" in description:
        raise ArgumentError(f"estimator '{name}' needs a one-line description", argument="description")

    def decorate(cls):
        old = _SPECS.get(name)
        if old is not None and old.cls.__qualname__ != cls.__qualname__:
            raise ArgumentError(f"estimator '{name}' is registered twice ({old.cls.__module__}."
                                f"{old.cls.__qualname__} and {cls.__module__}.{cls.__qualname__})",
                                argument="name")
        _SPECS[name] = EstimatorSpec(name, cls, options, motions, description,
                                     None if measurements is None else tuple(measurements), bool(can_smooth),
                                     build, table, bool(imm_mode), bool(standalone), build_filter,
                                     imm_child if imm_mode else None, check, dict(keys or {}))
        return cls
    return decorate


def _entry_points() -> dict:
    """name -> entry point of the group ``mixnav.estimators`` (nothing imported)."""
    from importlib.metadata import entry_points
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def estimator_names(standalone_only: bool = True) -> list[str]:
    """Every estimator name (built-in, then installed plug-ins, then registered at run time);
    imports no estimator module. ``standalone_only``: leave out the IMM-only modes."""
    imm_only = builtin_imm_only()
    names = [n for n in builtin_modules() if not (standalone_only and n in imm_only)]
    names += [n for n in _entry_points() if n not in names]
    names += [n for n, s in _SPECS.items() if n not in names and (s.standalone or not standalone_only)]
    return names


def estimator_spec(name: str) -> EstimatorSpec:
    """The registration of ``name`` (its module imported now); unknown: an
    :class:`ArgumentError` (argument ``estimator``) listing the registered names."""
    if name not in _SPECS:
        module = builtin_modules().get(name)
        if module is not None:
            import_module(module)
        else:
            ep = _entry_points().get(name)
            if ep is not None:
                ep.load()
    try:
        spec = _SPECS[name]
    except KeyError:
        raise ArgumentError(f"unknown estimator '{name}' (known: {', '.join(estimator_names())})",
                            argument="estimator") from None
    for variant in variant_modules().get(name, ()):   # however the estimator's module was imported
        import_module(variant)
    return spec


def check_motion(name: str, motion: str) -> EstimatorSpec:
    """The spec of ``name`` if it runs on ``motion``; otherwise an :class:`ArgumentError`
    (argument ``estimator``) saying which do."""
    spec = estimator_spec(name)
    if not spec.standalone:
        raise ArgumentError(f"estimator '{name}' is only a mode of an IMM (estimator = \"imm\")",
                            argument="estimator")
    if motion not in spec.motions:
        raise ArgumentError(f"estimator '{name}' does not run on the {motion} motion model (it runs on: "
                            f"{', '.join(spec.motions)})", argument="estimator")
    return spec


def imm_mode_names() -> list[str]:
    """The registered estimators that can be a mode of an IMM (imports every estimator module)."""
    return [n for n in estimator_names(standalone_only=False) if estimator_spec(n).imm_mode]


def table_owners(table: str) -> list[str]:
    """The registered estimators whose settings are the method's (or a mode's) ``[table]``
    (imports every estimator module: asked when a file puts a table where it does not belong)."""
    return [n for n in estimator_names(standalone_only=False) if estimator_spec(n).table == table]


def validate_table(table: str, estimator: str | None, values):
    """A method's (or an IMM mode's) ``[table]``, validated by the options model of the
    estimator it belongs to: the entry's ``estimator`` if its settings are that table,
    otherwise the table's first owner (the entry is then refused by
    :func:`table_problem`; its content is checked first, as a file is read top-down).
    Nested errors keep their keys (pydantic's ValidationError, raised as is)."""
    spec = None
    if estimator is not None:
        try:
            spec = estimator_spec(estimator)
        except ArgumentError:
            spec = None
    if spec is None or spec.table != table:
        owners = table_owners(table)
        if not owners:
            raise ValueError(f"no registered estimator takes a [{table}] table")
        spec = estimator_spec(owners[0])
    return spec.options.model_validate(values)


def table_problem(entry, estimator: str, tables) -> str | None:
    """What is wrong with the estimator ``tables`` (field names) of ``entry`` for its
    ``estimator``: a table of another estimator, or a required table missing; None if
    nothing."""
    try:
        spec = estimator_spec(estimator)
    except ArgumentError:
        return None                     # the estimator's own check says it
    for table in tables:
        if getattr(entry, table, None) is not None and spec.table != table:
            owners = table_owners(table)
            if len(owners) == 1 and estimator_spec(owners[0]).default_options() is None:
                return _go_together(owners[0], table)
            need = " or ".join(f'estimator = "{n}"' for n in owners)
            return f"{_article(table)} [{table}] table needs {need}"
    if spec.table in tables and getattr(entry, spec.table, None) is None and spec.default_options() is None:
        return _go_together(estimator, spec.table)
    return None


def _article(word: str) -> str:
    return "an" if word[:1] in "aeiou" else "a"


def _go_together(estimator: str, table: str) -> str:
    return f'estimator = "{estimator}" and {_article(table)} [{table}] table go together'


@dataclass(frozen=True)
class TrainingNeed:
    """What an estimator learns from a simulated training stretch before a scenario's runs
    (:func:`mixnav.experiment.run` draws one stretch for all methods): ``residuals``, the
    offline mixture learners' (observable kinds, samples, whether the process noise is
    learned too); ``series``, the coloured-noise fit's (kinds, samples, process). An
    estimator says what it needs through its options' ``training_needs()``."""
    residuals: tuple[tuple[str, ...], int, bool] | None = None
    series: tuple[tuple[str, ...], int, bool] | None = None


def training_needs(entry) -> list[TrainingNeed]:
    """The training a method's (or an IMM mode's) ``entry`` needs: its estimator's options
    (:func:`entry_options`) asked through ``training_needs()``; none when they have no such
    method."""
    options = entry_options(entry, estimator_spec(entry.estimator))
    ask = getattr(options, "training_needs", None)
    return list(ask()) if ask is not None else []


def entry_options(entry, spec: EstimatorSpec):
    """The settings ``spec`` is built from for a method's (or mode's) ``entry``: its own table
    (validated, or every default when absent) or its ``[options]``."""
    if spec.table is not None:
        table = getattr(entry, spec.table, None)
        return table if table is not None else spec.options()
    return dict(getattr(entry, "options", None) or {})


def checked_options(name: str | None, options: dict) -> dict:
    """An entry's ``[options]`` checked against the options model the estimator ``name``
    registered: the same keys, validated values. A ValueError whose message starts with the
    option's key (``options.<key>: ...``), which the config's loader makes the error's key;
    an estimator whose settings are a table of its own takes no ``[options]``."""
    if name is None or not options:
        return options
    try:
        spec = estimator_spec(name)
    except ArgumentError:
        return options          # the estimator's own check says it
    if spec.table is not None:
        raise ValueError(f"estimator \"{name}\" takes its settings from its own table ([{spec.table}]), "
                         "not [options]")
    try:
        checked = spec.parse_options(options)
    except ArgumentError as exc:
        raise ValueError(f"options.{exc.argument}: {exc.message}") from None
    return {k: getattr(checked, k) for k in options}


def check_entry(entry, estimator: str, tables, measurements, mode: bool) -> None:
    """The whole-entry checks of a method's or a mode's ``estimator``: its tables
    (:func:`table_problem`), then the registration's ``check`` with the ``measurements``
    names the entry can use; a ValueError saying what is wrong."""
    problem = table_problem(entry, estimator, tables)
    if problem:
        raise ValueError(problem)
    try:
        spec = estimator_spec(estimator)
    except ArgumentError:
        return
    if spec.check is not None:
        spec.check(entry_options(entry, spec), list(measurements), mode)
