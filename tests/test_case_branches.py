"""One library for both cases: observers/ and analysis/ choose by what the model declares, not by the case.

A method's engine, a refusal or a figure's panels come from what the model
declares (:class:`fmscal.plant.Model`: ``linear_channels``, ``attitude``,
``paper_equations``, ``residual_panels``, ...) and from the registry's table
of engines (:data:`fmscal.observers._registry.ENGINES`). This file keeps it so:
an AST scan counts the places that branch on the case and allows at most
:data:`MAX_SITES`, all in the registry module.

What counts. A *case test* is any of:

1. ``isinstance(x, C)`` or ``issubclass(x, C)`` where ``C`` (or an entry of
   a tuple ``C``) is a class of one case: named ``Payload`` or starting with
   ``Planar`` or ``Spatial`` (``PlanarModel``, ``SpatialModel``,
   ``SpatialPayload``, ``SpatialScenario``, ...);
2. a comparison (``==``, ``!=``, ``in``, ``not in``, ``is``, ``is not``) with
   a case's name, ``"planar"``, ``"spatial"`` or ``"table"`` (a string, or a
   tuple, list or set holding one);
3. a comparison that reads a case's name: the attribute ``kind`` or ``name``
   of an object called ``model``, ``log``, ``scenario``, ``sc``, ``payload``,
   ``data``, ``table`` or ``calibration`` (``model.name``,
   ``self.model.name``, ``log.kind``; ending in ``_model`` or ``_log`` too),
   ``getattr(x, "kind", ...)``, or a call of ``log_kind``;
4. a size compared (``==``, ``!=``, ``in``, ``not in``) with 3 or 6 (the
   planar and the spatial reading): ``len(...)``, an attribute ``size``,
   ``n_w``, ``n_pose``, ``nq``, ``nv`` or ``nx``, or ``.shape[...]``; except a
   ``len(...)`` in the test of an ``if`` whose body only raises (the shape
   check of one argument, ``if len(rho) != 3: raise ...``);
5. a test (of ``if``/``elif``, ``while``, a conditional expression,
   ``assert``, a comprehension's ``if``) that reads a name or an attribute
   whose identifier holds ``planar`` or ``spatial`` (``if spatial:``,
   ``if self._spatial:``, ``if name in SPATIAL_SCENARIOS:``);
6. ``hasattr(x, "a")`` or ``getattr(x, "a", default)`` in such a test, ``x``
   an object called as in rule 3 and ``a`` an attribute that one case's model
   or payload has and the other's lacks (``hasattr(model, "gravity")``
   standing in for the case);
7. a subscript by a case's name (``table[log.kind]``, ``table[model.name]``):
   a dispatch on the case.

A *branch site* is a statement holding at least one case test (a statement
over several lines is one site, at its first line). What does not count: a
message or help text that names the case (a string is not a test), a test of
a declaration (``if model.linear_channels:``), and a lookup in a table keyed by
a declaration (:func:`fmscal.observers._registry.engine_class`).
"""

import ast
from pathlib import Path

import numpy as np
import pytest

from fmscal import plant
from fmscal.observers import AdaptiveObserver, AugmentedEKF, LeastSquares, MaximumLikelihood
from fmscal.observers._registry import ENGINES, engine_class
from fmscal.observers.adaptive._adaptive import SpatialAdaptiveObserver
from fmscal.observers.batch._least_squares import SpatialLeastSquares
from fmscal.plant.physics._model import Model, PlanarModel, SpatialModel
from fmscal.plant.scenarios._spatial import TOOL

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("observers", "analysis")
#: The one module where the toolkit may tell its cases apart, and how many places there at most.
REGISTRY = "observers/_registry.py"
MAX_SITES = 3
#: Files excused from the count (each must name a file that exists): none since calibrate became one workflow
#: on the log's model (analysis/_calibrate.py) and the command line and the calibration file read the models'
#: declarations.
ALLOWED = set()

_CASE_NAMES = {"planar", "spatial", "table"}
_CASE_OBJECTS = {"model", "log", "scenario", "sc", "payload", "data", "table", "calibration"}
_SIZES = {"size", "n_w", "n_pose", "nq", "nv", "nx"}
_EQUALITY = (ast.Eq, ast.NotEq, ast.In, ast.NotIn, ast.Is, ast.IsNot)


def _one_case_attributes():
    """Attributes one case's model or payload has and the other's lacks (rule 6)."""
    planar, spatial = PlanarModel(plant.PAPER_PAYLOAD), SpatialModel(TOOL)
    pairs = ((planar, spatial), (planar.payload, spatial.payload))
    return {a for p, s in pairs for a in set(dir(p)) ^ set(dir(s)) if not a.startswith("__")}


_ONE_CASE = _one_case_attributes()


def _identifier(node):
    """The last name of an expression: ``self.model.name`` -> ``name``, ``f(x)`` -> ``f``, ``a[0]`` -> ``a``."""
    while isinstance(node, (ast.Subscript, ast.Call)):
        node = node.value if isinstance(node, ast.Subscript) else node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def _case_class(node):
    if isinstance(node, ast.Tuple):
        return any(_case_class(e) for e in node.elts)
    name = _identifier(node)
    return name == "Payload" or name.startswith(("Planar", "Spatial"))


def _case_name(node):
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str) and node.value in _CASE_NAMES
    return isinstance(node, (ast.Tuple, ast.List, ast.Set)) and any(_case_name(e) for e in node.elts)


def _reads_case(node):
    """Rule 3's operand (and rule 7's subscript): the case's name read off a model, a log, ..."""
    if isinstance(node, ast.Call):
        name = _identifier(node.func)
        kind = (name == "getattr" and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant)
                and node.args[1].value == "kind")
        return kind or name == "log_kind"
    return isinstance(node, ast.Attribute) and node.attr in ("kind", "name") and _case_object(node.value)


def _case_object(node):
    """An object called ``model``, ``log``, ... (rule 3): ``self.model``, ``log``, ``spatial_model``."""
    owner = _identifier(node).lower()
    return owner in _CASE_OBJECTS or owner.endswith(("_model", "_log"))


def _size(node):
    if isinstance(node, ast.Call):
        return _identifier(node.func) == "len"
    if isinstance(node, ast.Subscript):
        return isinstance(node.value, ast.Attribute) and node.value.attr == "shape"
    return isinstance(node, ast.Attribute) and node.attr in _SIZES


def _three_or_six(node):
    if isinstance(node, ast.Constant):
        return type(node.value) is int and node.value in (3, 6)
    return isinstance(node, (ast.Tuple, ast.List, ast.Set)) and any(_three_or_six(e) for e in node.elts)


def _names_case(node):
    """Rule 5: the expression reads a name or attribute whose identifier holds planar or spatial."""
    for n in ast.walk(node):
        ident = n.id if isinstance(n, ast.Name) else n.attr if isinstance(n, ast.Attribute) else ""
        if "planar" in ident.lower() or "spatial" in ident.lower():
            return True
    return False


def _probes_one_case(node):
    """Rule 6: ``hasattr``/``getattr`` with a default, of an attribute only one case has, in the expression."""
    for n in ast.walk(node):
        if (isinstance(n, ast.Call) and _identifier(n.func) in ("hasattr", "getattr") and len(n.args) >= 2
                and (_identifier(n.func) == "hasattr" or len(n.args) == 3) and _case_object(n.args[0])
                and isinstance(n.args[1], ast.Constant) and n.args[1].value in _ONE_CASE):
            return True
    return False


def _only_raises(statement):
    return isinstance(statement, ast.If) and not statement.orelse and all(isinstance(s, ast.Raise)
                                                                          for s in statement.body)


def _case_test(node, statement):
    """Which rule ``node`` breaks (rules 1-4, 7), or None."""
    if isinstance(node, ast.Call) and _identifier(node.func) in ("isinstance", "issubclass") and len(node.args) == 2:
        return "isinstance" if _case_class(node.args[1]) else None
    if isinstance(node, ast.Compare) and all(isinstance(op, _EQUALITY) for op in node.ops):
        operands = [node.left, *node.comparators]
        if any(_case_name(o) for o in operands):
            return "case name"
        if any(_reads_case(o) for o in operands):
            return "reads the case"
        sized = [o for o in operands if _size(o)]
        if sized and any(_three_or_six(o) for o in operands):
            shape_check = _only_raises(statement) and all(isinstance(o, ast.Call) for o in sized)
            return None if shape_check else "size 3 or 6"
    if isinstance(node, ast.Subscript) and _reads_case(node.slice):
        return "dispatch on the case"
    return None


def _tests_of(node):
    if isinstance(node, (ast.If, ast.While, ast.IfExp, ast.Assert)):
        return [node.test]
    return list(node.ifs) if isinstance(node, ast.comprehension) else []


def branch_sites(source, filename="<source>"):
    """The branch sites on the case in ``source`` (module docstring): ``{(filename, line): rule}``."""
    sites = {}

    def visit(node, statement):
        statement = node if isinstance(node, ast.stmt) else statement
        rule = _case_test(node, statement)
        if rule is not None:
            sites.setdefault((filename, statement.lineno), rule)
        for child in ast.iter_child_nodes(node):
            visit(child, statement)
        # rules 5 and 6 after the test's own expressions, so that a site says its most specific rule
        tests = _tests_of(node)
        if any(_names_case(t) for t in tests):
            sites.setdefault((filename, statement.lineno), "case-named test")
        if any(_probes_one_case(t) for t in tests):
            sites.setdefault((filename, statement.lineno), "attribute of one case")

    tree = ast.parse(source)
    visit(tree, tree)
    return sites


def _scan():
    sites = {}
    for folder in SCANNED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            sites.update(branch_sites(path.read_text(), path.relative_to(ROOT).as_posix()))
    return sites


def test_observers_and_analysis_branch_on_the_case_only_in_the_registry():
    sites = {site: rule for site, rule in _scan().items() if site[0] not in ALLOWED}
    elsewhere = sorted(f"{f}:{line} ({rule})" for (f, line), rule in sites.items() if f != REGISTRY)
    assert not elsewhere, ("a branch on the case outside the registry: ask the model's declarations or "
                           "fmscal.observers._registry.ENGINES instead:\n" + "\n".join(elsewhere))
    assert len(sites) <= MAX_SITES, f"{len(sites)} branch sites on the case in {REGISTRY}; at most {MAX_SITES}"


def test_the_allowlist_names_files_that_exist():
    missing = sorted(f for f in ALLOWED if not (ROOT / f).is_file())
    assert not missing, f"stale entries in ALLOWED (renamed or gone): {missing}"


@pytest.mark.parametrize("source, rule", [
    ("def f(model):\n    if isinstance(model, SpatialModel):\n        return ErrorStateEKF\n", "isinstance"),
    ("def f(log):\n    if log.kind == 'spatial':\n        return 1\n", "case name"),
    ("x = isinstance(payload, (Payload, SpatialPayload))\n", "isinstance"),
    ("def f(self):\n    if self.model.name not in self.models:\n        return 1\n", "reads the case"),
    ("def f(log, other):\n    return 1 if log.kind != other.kind else 2\n", "reads the case"),
    ("def f(truth):\n    if truth.schedule.size == 6:\n        return 1\n", "size 3 or 6"),
    ("def f(rho):\n    if len(rho) == 3:\n        return 1\n", "size 3 or 6"),
    ("def f(spatial):\n    if spatial:\n        return 1\n", "case-named test"),
    ("def f(self):\n    return self._a() if self._spatial else self._b()\n", "case-named test"),
    ("def f(model):\n    if hasattr(model, 'gravity'):\n        return 1\n", "attribute of one case"),
    ("def f(log):\n    return STEPS[log.kind]\n", "dispatch on the case"),
])
def test_the_counter_catches_a_planted_branch(source, rule):
    sites = branch_sites(source)
    assert list(sites.values()) == [rule], sites


@pytest.mark.parametrize("source", [
    "def f(model):\n    if model.linear_channels:\n        return 1\n",                  # a declaration
    "def f(cls, model):\n    return next((e for (m, d, v), e in T.items()\n"                 # a declaration's table
    "                 if m is cls and getattr(model, d) == v), cls)\n",
    "def f(model):\n    raise E(f'{model.name} is not planar; a spatial model has its own law')\n",   # a message
    "def f(rho):\n    if len(rho) != 3:\n        raise E('rho takes 3 numbers')\n",            # a shape check
    "def f(rows):\n    return [r for r in rows if len(r) >= 3]\n",                             # not a case's size
    "def f(v):\n    return v.kind == v.POSITIONAL_OR_KEYWORD\n",                             # not a case's kind
    "def f(log):\n    return hasattr(log, 'columns')\n",                                     # both cases have it
])
def test_the_counter_leaves_declarations_and_messages_alone(source):
    assert branch_sites(source) == {}


def test_the_counter_takes_a_multi_line_statement_as_one_site():
    source = "def f(log, model):\n    if (log.kind == 'spatial'\n            and isinstance(model, SpatialModel)):\n" \
             "        return 1\n"
    assert list(branch_sites(source)) == [("<source>", 2)]


class _Arm(SpatialModel):
    """The spatial model under another name: engines go by its declarations, not by its name or class."""

    name = "arm"


class _Angle(PlanarModel):
    name = "turntable"


@pytest.mark.parametrize("model", [SpatialModel(TOOL), _Arm(TOOL)])
def test_a_model_with_a_quaternion_attitude_gets_the_spatial_engines(model):
    assert type(AugmentedEKF(model)) is AugmentedEKF          # one EKF: an error state on every model
    assert type(AdaptiveObserver(model)) is SpatialAdaptiveObserver
    assert type(LeastSquares(model, offset=True)) is SpatialLeastSquares
    assert type(MaximumLikelihood(model)) is MaximumLikelihood
    for cls in (AugmentedEKF, AdaptiveObserver, LeastSquares):
        assert cls.refusal(model) is None and cls.runs_on(model)


@pytest.mark.parametrize("model", [PlanarModel(plant.PAPER_PAYLOAD), _Angle(plant.PAPER_PAYLOAD)])
def test_a_model_linear_in_its_channels_runs_every_method_as_its_own_class(model):
    for cls in (AugmentedEKF, AdaptiveObserver, LeastSquares):
        assert engine_class(cls, model) is cls and type(cls(model)) is cls


def test_every_engine_is_a_subclass_of_its_method_and_keyed_by_a_declaration():
    for (method, declaration, _), engine in ENGINES.items():
        assert issubclass(engine, method) and engine is not method
        assert hasattr(Model, declaration), f"{declaration} is not a declaration of plant.Model"


def test_a_planar_models_pose_residuals_are_the_generic_difference():
    """PlanarModel.pose_residuals (one product) is Model.pose_residuals (difference row by row)."""
    rng = np.random.default_rng(7)
    model = PlanarModel(plant.PAPER_PAYLOAD)
    states, poses = rng.normal(size=(20, model.nx)), rng.normal(size=(20, model.n_pose))
    np.testing.assert_allclose(model.pose_residuals(states, poses), Model.pose_residuals(model, states, poses),
                               rtol=0, atol=1e-15)
    assert sorted(c for _, _, cols in model.residual_panels for c in cols) == list(range(model.nv))
