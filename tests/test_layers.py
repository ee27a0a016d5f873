"""The package's layers point one way, thresholds and methods are written down once.

* the import graph of ``src/sixdpose`` (every ``import`` / ``from`` statement anywhere in a file, module- and
  function-level alike, relative ones resolved) has no cycle between packages or between modules, and no
  import from a lower layer to a higher one (:data:`LAYERS`);
* ``pose/`` uses ``sixdpose.registration`` through its public names only;
* no threshold of the evaluation protocol is typed outside :mod:`sixdpose.constants`, no pose is filled into
  ``np.eye(4)`` by hand outside :func:`sixdpose.geometry.X_from`;
* the method and profile lists of ``mk/`` are the ones of :mod:`sixdpose.registry`.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

from sixdpose import constants, registry

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
PKG = SRC / "sixdpose"

#: The layers, bottom to top: a module may import modules of its own layer or of a lower one. A module
#: belongs to the layer of its longest listed prefix; every ``cli`` module (the top-level one and each
#: stage's ``<stage>.cli``) belongs to the top layer.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("base", ("sixdpose", "sixdpose.errors", "sixdpose.constants", "sixdpose.fileio", "sixdpose.config",
              "sixdpose.logs", "sixdpose.runs", "sixdpose.geometry", "sixdpose.registry", "sixdpose.schemas",
              "sixdpose.options", "sixdpose.graph", "sixdpose.workers",
              "sixdpose.lazy")),
    ("readers", ("sixdpose.datasets", "sixdpose.assets", "sixdpose.artifacts")),
    ("scoring", ("sixdpose.evaluation",)),
    ("stages", ("sixdpose.generation", "sixdpose.segmentation", "sixdpose.registration", "sixdpose.pose",
                "sixdpose.training")),
    ("reporting", ("sixdpose.reporting",)),
    ("cli", ("sixdpose.cli", "sixdpose.__main__")),
)
_RANK = {name: i for i, (name, _) in enumerate(LAYERS)}


# --------------------------------------------------------------------------------------------
# the import graph
# --------------------------------------------------------------------------------------------
def _modules(src: Path = SRC) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``) of every module under ``src``."""
    out = {}
    for p in sorted(src.rglob("*.py")):
        parts = list(p.relative_to(src).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        if is_pkg:
            parts = parts[:-1]
        out[".".join(parts)] = (p, is_pkg)
    return out


def _imported(module: str, is_pkg: bool, node: ast.Import | ast.ImportFrom, known) -> list[str]:
    """The dotted names an import statement of ``module`` refers to (a submodule where ``from X import Y``
    names one, else ``X``)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        base = module.split(".") if is_pkg else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        prefix = ".".join(base + ([node.module] if node.module else []))
    else:
        prefix = node.module or ""
    return [f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in known else prefix for a in node.names]


def import_graph(src: Path = SRC, top: str = "sixdpose") -> dict[str, set[str]]:
    """Module -> the package modules it imports (every import statement in the file, at any depth)."""
    mods = _modules(src)
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, (path, is_pkg) in mods.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for target in _imported(m, is_pkg, node, mods):
                if target.split(".")[0] != top:
                    continue
                while target not in mods and "." in target:  # an attribute of a module: the module
                    target = target.rsplit(".", 1)[0]
                if target in mods and target != m:
                    graph[m].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def layer_of(module: str) -> str | None:
    """The layer of a module (None: in no layer)."""
    if module.endswith(".cli"):
        return "cli"
    best = None
    for name, prefixes in LAYERS:
        for p in prefixes:
            inside = module == p or (module.startswith(p + ".") and p != "sixdpose")
            if inside and (best is None or len(p) > len(best[1])):
                best = (name, p)
    return None if best is None else best[0]


def unit_of(module: str) -> str:
    """The node of the package-level graph: the package under ``sixdpose`` (a cli module is its own node)."""
    if layer_of(module) == "cli":
        return module
    return ".".join(module.split(".")[:2])


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The module graph collapsed onto :func:`unit_of`."""
    out: dict[str, set[str]] = defaultdict(set)
    for a, targets in graph.items():
        for b in targets:
            if unit_of(a) != unit_of(b):
                out[unit_of(a)].add(unit_of(b))
    return dict(out)


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """``"a (layer) -> b (layer)"`` for every import of a higher layer, and every module in no layer."""
    bad = [f"{m}: in no layer (add it to LAYERS in tests/test_layers.py)" for m in sorted(graph) if layer_of(m) is None]
    for a in sorted(graph):
        for b in sorted(graph[a]):
            la, lb = layer_of(a), layer_of(b)
            if la is not None and lb is not None and _RANK[lb] > _RANK[la]:
                bad.append(f"{a} ({la}) imports {b} ({lb})")
    return bad


GRAPH = import_graph()


def test_the_graph_sees_function_level_and_relative_imports():
    assert "sixdpose.errors" in GRAPH["sixdpose.cli"]  # module level, relative
    assert "sixdpose.registration.runner" in GRAPH["sixdpose.reporting.compare"]  # inside a function
    assert "sixdpose.pose.infer" in GRAPH["sixdpose.reporting.compare"]
    assert "sixdpose.datasets.base" in GRAPH["sixdpose.datasets.readers"]


def test_no_import_cycle_between_modules():
    assert cycles(GRAPH) == []


def test_no_import_cycle_between_packages():
    assert cycles(package_graph(GRAPH)) == []


def test_layers_point_one_way():
    assert layer_violations(GRAPH) == []


def test_the_checks_catch_a_cycle_and_an_upward_import(tmp_path):
    """The checks themselves fail where they should: on a tree with a function-level cycle and an import of
    the reporting layer from a reader."""
    pkg = tmp_path / "sixdpose"
    for d in ("", "datasets", "reporting"):
        (pkg / d).mkdir(exist_ok=True)
        (pkg / d / "__init__.py").write_text("")
    (pkg / "datasets" / "a.py").write_text("def f():\n    from . import b\n")
    (pkg / "datasets" / "b.py").write_text("from .a import f\n")
    (pkg / "datasets" / "c.py").write_text("def g():\n    from ..reporting.report import h\n")
    (pkg / "reporting" / "report.py").write_text("def h():\n    pass\n")
    g = import_graph(tmp_path)
    assert cycles(g) == [["sixdpose.datasets.a", "sixdpose.datasets.b"]]
    assert layer_violations(g) == ["sixdpose.datasets.c (readers) imports sixdpose.reporting.report (reporting)"]
    (pkg / "reporting" / "report.py").write_text("from ..datasets import c\n")
    assert cycles(package_graph(import_graph(tmp_path))) == [["sixdpose.datasets", "sixdpose.reporting"]]


# --------------------------------------------------------------------------------------------
# pose/ uses the registration stage through its public names
# --------------------------------------------------------------------------------------------
def _all_of(init: Path) -> set[str]:
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return set(ast.literal_eval(node.value))
    raise AssertionError(f"{init}: no __all__")


def registration_uses(src: Path = SRC) -> list[str]:
    """``file: statement`` for every import of ``sixdpose.registration`` under ``pose/`` that is not
    ``from sixdpose.registration import <public name>``."""
    mods = _modules(src)
    public = _all_of(src / "sixdpose" / "registration" / "__init__.py")
    bad = []
    for m, (path, is_pkg) in mods.items():
        if not m.startswith("sixdpose.pose"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            where = f"{path.relative_to(src)}:{node.lineno}"
            if isinstance(node, ast.Import):
                bad += [f"{where}: import {a.name}" for a in node.names if a.name.startswith("sixdpose.registration")]
                continue
            base = m.split(".") if is_pkg else m.split(".")[:-1]
            module = (".".join(base[: len(base) - (node.level - 1)] + ([node.module] if node.module else []))
                      if node.level else node.module or "")
            if module == "sixdpose.registration":
                bad += [f"{where}: {a.name} is not public" for a in node.names if a.name not in public]
            elif module.startswith("sixdpose.registration.") or (module == "sixdpose" and any(
                    a.name == "registration" for a in node.names)):
                bad.append(f"{where}: from {module} import {', '.join(a.name for a in node.names)}")
    return bad


def test_pose_imports_only_registrations_public_names():
    assert registration_uses() == []


def test_the_public_name_check_fails_on_a_submodule_import(tmp_path):
    for d in ("sixdpose", "sixdpose/pose", "sixdpose/registration"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "__init__.py").write_text("")
    (tmp_path / "sixdpose/registration/__init__.py").write_text('__all__ = ["refine_pose"]\n')
    (tmp_path / "sixdpose/pose/infer.py").write_text(
        "def f():\n    from ..registration import refine_pose, _private\n    from ..registration.methods import x\n")
    assert registration_uses(tmp_path) == ["sixdpose/pose/infer.py:2: _private is not public",
                                           "sixdpose/pose/infer.py:3: from sixdpose.registration.methods import x"]


# --------------------------------------------------------------------------------------------
# named constants and one pose helper
# --------------------------------------------------------------------------------------------
#: The thresholds that live in sixdpose.constants, and the names that mark a number as one of them.
THRESHOLDS = {constants.MIN_VISIBLE_PX, constants.ADD_THRESHOLD, constants.MIN_DETECTION_SCORE,
              constants.DETECTION_SCORE_FLOOR}
THRESHOLD_NAME = re.compile(r"min_px|px_visib|visib|score|thresh")
#: Modules exempt from the scan: the constants themselves, the paper's published figures.
EXEMPT = {"constants.py", "reporting/paper.py"}
#: Unrelated numbers under a threshold-like name: (file, name).
ALLOWED = {
    ("segmentation/infer.py", "mask_thresh"),  # binarisation of Mask R-CNN's soft masks, not a score
    ("generation/sensors.py", "dark_threshold"),  # luminance below which the depth sensor drops pixels
}


def _name(node) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str):
        return node.slice.value
    return None


def _numbers(node) -> list[ast.Constant]:
    return [n for n in ast.walk(node) if isinstance(n, ast.Constant) and type(n.value) in (int, float)
            and n.value in THRESHOLDS]


def threshold_literals(tree: ast.AST, rel: str) -> list[str]:
    """``file:line name=value`` for each threshold number typed under a threshold-like name: a parameter
    default, a keyword argument (``argparse``'s ``default=`` under the option's name), ``.get("name", value)``
    or a comparison with a named value."""
    hits: list[tuple[int, str, object]] = []

    def check(name, value_node):
        if name and THRESHOLD_NAME.search(name) and (rel, name) not in ALLOWED:
            hits.extend((n.lineno, name, n.value) for n in _numbers(value_node))

    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            a = node.args
            pos = a.posonlyargs + a.args
            for arg, d in zip(pos[len(pos) - len(a.defaults):], a.defaults, strict=True):
                check(arg.arg, d)
            for arg, d in zip(a.kwonlyargs, a.kw_defaults, strict=True):
                if d is not None:
                    check(arg.arg, d)
        elif isinstance(node, ast.Call):
            option = next((k.value.value for k in node.keywords
                           if k.arg == "dest" and isinstance(k.value, ast.Constant)), None)
            first = node.args[0] if node.args else None
            if option is None and isinstance(first, ast.Constant) and isinstance(first.value, str):
                option = first.value.lstrip("-").replace("-", "_")
            for k in node.keywords:
                check(option if k.arg == "default" else k.arg, k.value)
            if isinstance(node.func, ast.Attribute) and node.func.attr == "get" and len(node.args) == 2:
                check(option, node.args[1])
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            check(_name(node.target), node.value)
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                check(_name(t), node.value)
        elif isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            names = [n for n in map(_name, sides) if n]
            for side in sides:
                if isinstance(side, ast.Constant):
                    for n in names:
                        check(n, side)
    return [f"{rel}:{line} {name}={value}" for line, name, value in sorted(set(hits), key=lambda h: (h[0], h[1]))]


def hand_filled_poses(tree: ast.AST, rel: str) -> list[str]:
    """``file:line`` of each ``X = np.eye(4)`` (or ``np.identity(4)``) in a scope where ``X`` is also filled
    by slicing (``X[...] = ...``)."""
    out = set()
    scopes = [tree] + [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
    for scope in scopes:
        eyes: dict[str, list[int]] = defaultdict(list)
        for node in ast.walk(scope):
            if (isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)
                    and isinstance(node.value, ast.Call) and isinstance(node.value.func, ast.Attribute)
                    and node.value.func.attr in ("eye", "identity") and node.value.args
                    and isinstance(node.value.args[0], ast.Constant) and node.value.args[0].value == 4):
                eyes[node.targets[0].id].append(node.lineno)
        for node in ast.walk(scope):
            for t in node.targets if isinstance(node, ast.Assign) else []:
                for sub in (t.elts if isinstance(t, ast.Tuple) else [t]):
                    if isinstance(sub, ast.Subscript) and isinstance(sub.value, ast.Name) and sub.value.id in eyes:
                        out.update(f"{rel}:{line}" for line in eyes[sub.value.id])
    return sorted(out, key=lambda h: int(h.rsplit(":", 1)[1]))


def _sources():
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG).as_posix()
        yield rel, ast.parse(p.read_text(encoding="utf-8"))


def test_no_threshold_literal_outside_the_constants():
    hits = [h for rel, tree in _sources() if rel not in EXEMPT for h in threshold_literals(tree, rel)]
    assert hits == []


def test_no_hand_filled_pose_outside_the_helper():
    hits = [h for rel, tree in _sources() if rel != "geometry.py" for h in hand_filled_poses(tree, rel)]
    assert hits == []


def test_the_scans_catch_literals_and_hand_filled_poses():
    code = '''
def f(min_px: int = 400, *, score_thresh=0.5, smooth_rel=0.1):
    p.add_argument("--threshold", type=float, default=0.1)
    g(min_px=400 if masks == "gt" else 0, mask_thresh=0.5)
    keep = [d for d in dets if d.score >= 0.5]
    n = cfg.get("min_px", 400)
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    for z in (1.0, 2.0):
        X = np.eye(4)
        X[2, 3] = z
    return np.eye(4)


class C:
    score_thresh: float = 0.05
    low: float = 0.5
'''
    tree = ast.parse(code)
    assert threshold_literals(tree, "x.py") == [
        "x.py:2 min_px=400", "x.py:2 score_thresh=0.5", "x.py:3 threshold=0.1", "x.py:4 mask_thresh=0.5",
        "x.py:4 min_px=400", "x.py:5 score=0.5", "x.py:6 min_px=400", "x.py:16 score_thresh=0.05"]
    assert threshold_literals(tree, "segmentation/infer.py")[3:4] == ["segmentation/infer.py:4 min_px=400"]
    assert hand_filled_poses(tree, "x.py") == ["x.py:7", "x.py:10"]


def test_X_from():
    import numpy as np

    from sixdpose.geometry import X_from

    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    X = X_from(R, [0.1, 0.2, 0.3])
    assert X.shape == (4, 4) and X.dtype == np.float64
    np.testing.assert_array_equal(X[:3, :3], R)
    np.testing.assert_array_equal(X[:3, 3], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(X[3], [0, 0, 0, 1])
    np.testing.assert_allclose(X @ [1.0, 0.0, 0.0, 1.0], [0.1, 1.2, 0.3, 1.0])


# --------------------------------------------------------------------------------------------
# mk/ lists the registry's methods and profiles
# --------------------------------------------------------------------------------------------
def make_variables(path: Path) -> dict[str, str]:
    """``NAME := value`` / ``NAME = value`` definitions of a makefile (continuation lines joined; the last
    definition of a name wins; ``+=`` and conditionals are ignored)."""
    text = re.sub(r"\\\n\s*", " ", path.read_text(encoding="utf-8"))
    out = {}
    for line in text.splitlines():
        m = re.match(r"^([A-Za-z_][A-Za-z0-9_-]*)\s*(?::=|=)\s*(.*)$", line)
        if m and not line.startswith("\t"):
            out[m.group(1)] = m.group(2).split(" #")[0].strip()
    return out


def expand(value: str, variables: dict[str, str], keep=("RUNS", "WORKERS")) -> str:
    """``value`` with every ``$(NAME)`` of ``variables`` substituted (recursively), except ``keep``, which
    become ``{runs}`` / ``{workers}`` (the placeholders of :mod:`sixdpose.registry`)."""
    def one(m):
        name = m.group(1)
        if name in keep:
            return "{" + name.lower() + "}"
        return expand(variables[name], variables, keep)

    return " ".join(re.sub(r"\$\(([A-Za-z_][A-Za-z0-9_-]*)\)", one, value).split())


MK = make_variables(ROOT / "mk" / "reproduce.mk")
PROFILES_MK = make_variables(ROOT / "mk" / "profiles.mk")


def test_mk_method_lists_are_the_registry():
    hybrid = [m for m in registry.METHODS if m.kind == "hybrid"]
    assert MK["ALL_HYBRID"].split() == [m.key for m in hybrid if m.preset == "default"]
    # the paper-settings reruns: the same algorithm and ICP as one of ours, with --preset paper
    assert MK["PAPER_HYBRID"].split() == [m.key for m in hybrid if m.preset == "paper"]
    for m in hybrid:
        if m.preset == "paper":
            ours = registry.METHOD[m.key.removesuffix("_paper")]
            assert m.command == ours.command + " --preset paper" and ours.paper_acc, m.key
    assert {m.preset for m in registry.METHODS if m.kind == "learned"} == {"default"}
    assert MK["ALL_LEARNED"].split() == [m.key for m in registry.METHODS if m.kind == "learned"]
    assert MK["FEW_METHODS"].split() == [m.key for m in registry.METHODS if m.few]
    assert {m.kind for m in registry.METHODS} == {"hybrid", "learned"}
    from sixdpose.registration import METHODS as ALGORITHMS

    assert tuple(registry.HYBRID_ALGORITHMS) == ALGORITHMS
    for m in registry.METHODS + registry.REAL_METHODS:
        if m.kind == "hybrid":
            words = m.command.split()
            assert words[words.index("--method") + 1] in registry.HYBRID_ALGORITHMS, m.key


@pytest.mark.parametrize("method", registry.METHODS, ids=lambda m: m.key)
def test_mk_commands_are_the_registry(method):
    assert expand(MK[f"CMD_{method.key}"], MK) == method.command
    assert method.command.split()[0] == ("register" if method.kind == "hybrid" else "predict-pose")


def test_mk_real_frame_methods_are_the_registry():
    keys = [m.key for m in registry.REAL_METHODS]
    assert len(set(keys)) == len(keys)
    assert sorted(MK["YCBV_METHODS"].split()) == sorted(keys)
    for m in registry.REAL_METHODS:
        assert expand(MK[f"YCBV_CMD_{m.key}"], MK) == m.command, m.key
        assert m.command.split()[0] == ("register" if m.kind == "hybrid" else "predict-pose"), m.key


def test_mk_profiles_and_thresholds_are_the_registry_and_constants():
    assert tuple(PROFILES_MK["PROFILES"].split()) == registry.GRAPH_PROFILES
    for column in ("SEG", "POSE"):
        assert set(PROFILES_MK[column].split()) <= set(registry.STAGE_PROFILES), column
    from sixdpose.pose.config import PROFILES as POSE_PROFILES
    from sixdpose.pose.config import REFINER_PROFILES
    from sixdpose.segmentation.config import PROFILES as SEG_PROFILES

    for profiles in (POSE_PROFILES, REFINER_PROFILES, SEG_PROFILES):
        assert set(profiles) == set(registry.STAGE_PROFILES)
    assert f"--min-px {constants.MIN_VISIBLE_PX}" in MK["ARGS_register_gt"]
    assert f"--score-thresh {constants.MIN_DETECTION_SCORE}" in MK["ARGS_register_pred"]
    assert f"--score-thresh {constants.MIN_DETECTION_SCORE}" in MK["ARGS_predict-pose_pred"]


def test_the_mk_reader_expands_references():
    v = {"A": "x $(B) $(RUNS)/pose", "B": "y"}
    assert expand(v["A"], v) == "x y {runs}/pose"
