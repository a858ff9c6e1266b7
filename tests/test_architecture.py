"""The structural rules of the package (issue 14), read from its source with ``ast``.

- imports run one way: the graph of the package's modules, with the imports inside
  functions, has no cycle (imports under ``if TYPE_CHECKING:`` never run and are left out);
- no module imports a private name (``from .x import _y``, or ``x._y`` on a module
  imported from the package) of another;
- no function body (docstring excluded) is longer than ``MAX_LINES`` lines, and none
  takes more than ``MAX_PARAMS`` parameters (``self``/``cls`` not counted), except the
  public entry points that take an options object (a parameter named ``options`` and a
  ``**overrides``/``**kwargs``) for the parameter count;
- every citation ``method.md §N`` in the package, the tests, benchmarks, examples and the
  README names a section of docs/method.md;
- imports point down the layers of ``LAYERS`` (issue 20): the numerical core imports only
  itself, the errors and the standard library, numpy and scipy; nothing outside the
  applications (``apps``) imports them; the command line's flat option names
  (``flat_fields``, ``split``, ``parse_value``) are used only in ``options`` and ``apps``;
- no module is longer than ``MAX_MODULE_LINES`` lines.

Nothing is imported from the package: these tests read files only.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "modalmorph"
SRC = ROOT / "src" / PACKAGE
METHOD = ROOT / "docs" / "method.md"

MAX_LINES = 60  # lines of a function body, docstring excluded (issue 14)
MAX_PARAMS = 8  # parameters of a function, self/cls excluded (issue 14)
MAX_MODULE_LINES = 600  # lines of a module (issue 20)
# The layers, bottom up: a module imports modules of lower layers and of its own group.
# ("modalmorph" itself, the public front, sits above the verbs and below the apps.)
LAYERS = (
    ("errors", "version", "threads"),
    ("core",),  # numbers: shape, material, element, modes, solvers, model, dynamics, ...
    ("options",),  # the one schema of every option
    ("simulation", "matching", "io", "figures"),  # time integration, matching, files, plots
    ("pipeline", "datasets", "phantoms", "slide"),  # morph(); bundled data; phantoms;
    # tracked nodes' slide along an outline
    ("tracking",),  # track(): sequences, frame by frame through morph()
    ("cardiac", "pedobarography"),  # strain(), stance(), register_footprints()
    ("",),  # the package's __init__: the public API
    ("apps",),  # command line, runs, batch, web app, report
    ("__main__",),
)
CORE_DEPENDENCIES = {"numpy", "scipy"}  # and the standard library (method.md; style rule 6)
FLAT_NAMES = {"flat_fields", "split", "parse_value"}  # the command line's option namespace
_CITATION = re.compile(r"method\.md\W{0,3}§\s*(\d+(?:\.\d+)*)")
_HEADING = re.compile(r"^#{1,6}\s+§?(\d+(?:\.\d+)*)[.\s]", re.MULTILINE)


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package (subpackages too)."""
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        parts = (PACKAGE, *path.relative_to(SRC).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()
TREES = {name: ast.parse(path.read_text(), filename=str(path)) for name, path in
         MODULES.items()}


def _is_package(name: str) -> bool:
    return name in MODULES and MODULES[name].name == "__init__.py"


def _base(module: str, node: ast.ImportFrom) -> str | None:
    """The absolute module an ``ImportFrom`` reads from (None: outside the package)."""
    if node.level == 0:
        return node.module if node.module and (
            node.module == PACKAGE or node.module.startswith(PACKAGE + ".")) else None
    parts = module.split(".")
    if not _is_package(module):
        parts = parts[:-1]  # a module's level 1 is its package
    parts = parts[:len(parts) - (node.level - 1)]
    return ".".join(parts + ([node.module] if node.module else []))


def _type_checking_nodes(tree: ast.Module) -> set[int]:
    """ids of the nodes under ``if TYPE_CHECKING:`` (never executed)."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def _imports(module: str):
    """``(line, imported module, names)`` for each import of a package module in
    ``module``, at module level and inside functions; ``names`` are the imported names
    that are not themselves modules (empty for ``import x`` and module imports)."""
    tree = TREES[module]
    skip = _type_checking_nodes(tree)
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in MODULES:
                    yield node.lineno, alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            base = _base(module, node)
            if base is None:
                continue
            names = []
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in MODULES:  # from . import element: the module itself
                    yield node.lineno, sub, ()
                else:
                    names.append(alias.name)
            if names and base in MODULES:
                yield node.lineno, base, tuple(names)


def _graph() -> dict[str, dict[str, list[int]]]:
    """module -> {imported module: [lines]}, the package's own imports only."""
    graph = {name: {} for name in MODULES}
    for name in MODULES:
        for line, target, _ in _imports(name):
            if target != name:
                graph[name].setdefault(target, []).append(line)
    return graph


def _cycles(graph: dict[str, dict[str, list[int]]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_import_graph_has_no_cycle():
    graph = _graph()
    lines = []
    for comp in _cycles(graph):
        lines.append("cycle among " + ", ".join(comp) + ":")
        members = set(comp)
        for a in comp:
            for b, at in sorted(graph[a].items()):
                if b in members:
                    lines.append(f"  {a} -> {b} (line {', '.join(map(str, at))})")
    if lines:
        pytest.fail("import cycles in the package:\n" + "\n".join(lines), pytrace=False)


def _module_aliases(module: str) -> set[str]:
    """Local names bound to package modules by imports in ``module``."""
    names = set()
    for node in ast.walk(TREES[module]):
        if isinstance(node, ast.Import):
            names.update(a.asname for a in node.names if a.name in MODULES and a.asname)
        elif isinstance(node, ast.ImportFrom) and (base := _base(module, node)):
            names.update(a.asname or a.name for a in node.names
                         if f"{base}.{a.name}" in MODULES)
    return names


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def test_no_private_name_imported_from_another_module():
    offenders = []
    for module in MODULES:
        for line, target, names in _imports(module):
            for name in names:
                if _private(name) and target != module:
                    offenders.append(f"{module}:{line} imports {name} from {target}")
        aliases = _module_aliases(module)
        for node in ast.walk(TREES[module]):
            if (isinstance(node, ast.Attribute) and _private(node.attr)
                    and isinstance(node.value, ast.Name) and node.value.id in aliases):
                offenders.append(f"{module}:{node.lineno} uses {node.value.id}.{node.attr}")
    if offenders:
        pytest.fail("private names reached across modules (make them public or move "
                    "them):\n" + "\n".join(sorted(set(offenders))), pytrace=False)


def _walk(module: str, node, prefix: str, in_class: bool):
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
            yield module, prefix + child.name, child, in_class
            yield from _walk(module, child, prefix + child.name + ".", False)
        elif isinstance(child, ast.ClassDef):
            yield from _walk(module, child, prefix + child.name + ".", True)
        else:
            yield from _walk(module, child, prefix, in_class)


def _functions():
    """``(module, qualified name, node, is method)`` for every function of the package."""
    for module, tree in TREES.items():
        yield from _walk(module, tree, "", False)


def _body_lines(node) -> int:
    """Lines from the first statement after the docstring to the end of the function."""
    body = node.body
    if (len(body) > 1 and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
        body = body[1:]
    return node.end_lineno - body[0].lineno + 1


def _parameters(node, is_method: bool) -> list[str]:
    a = node.args
    names = [p.arg for p in (*a.posonlyargs, *a.args, *a.kwonlyargs)]
    static = any(isinstance(d, ast.Name) and d.id == "staticmethod"
                 for d in node.decorator_list)
    if is_method and not static and names and names[0] in ("self", "cls"):
        names = names[1:]
    return names + [f"*{p.arg}" for p in (a.vararg, a.kwarg) if p is not None]


def _options_entry_point(name: str, node) -> bool:
    """A public function taking an options object and keyword overrides."""
    a = node.args
    return (not name.rsplit(".", 1)[-1].startswith("_") and a.kwarg is not None
            and a.kwarg.arg in ("overrides", "kwargs")
            and "options" in [p.arg for p in (*a.posonlyargs, *a.args, *a.kwonlyargs)])


def test_functions_are_short():
    offenders = [(n, f"{module}.{name} (line {node.lineno}): {n} lines")
                 for module, name, node, _ in _functions()
                 if (n := _body_lines(node)) > MAX_LINES]
    if offenders:
        pytest.fail(f"functions over {MAX_LINES} lines (body without docstring), longest "
                    f"first:\n" + "\n".join(t for _, t in sorted(offenders, reverse=True)),
                    pytrace=False)


def test_functions_take_few_parameters():
    offenders = []
    for module, name, node, is_method in _functions():
        params = _parameters(node, is_method)
        if len(params) > MAX_PARAMS and not _options_entry_point(name, node):
            offenders.append((len(params), f"{module}.{name} (line {node.lineno}): "
                              f"{len(params)} parameters"))
    if offenders:
        pytest.fail(f"functions with more than {MAX_PARAMS} parameters (an entry point may "
                    f"take options=... and **overrides instead):\n"
                    + "\n".join(t for _, t in sorted(offenders, reverse=True)), pytrace=False)


def _group(module: str) -> str:
    """``core`` for ``modalmorph.core.model``, ``""`` for the package itself."""
    return module.split(".")[1] if "." in module else ""


def _layer(module: str) -> int:
    group = _group(module)
    for i, groups in enumerate(LAYERS):
        if group in groups:
            return i
    raise AssertionError(f"{module} is in no layer of LAYERS: add its group there")


def test_imports_point_down_the_layers():
    offenders = []
    for module, targets in _graph().items():
        for target, lines in targets.items():
            if _group(target) != _group(module) and _layer(target) >= _layer(module):
                offenders.append(f"{module} -> {target} (line {lines[0]}): layer "
                                 f"{_layer(module)} imports layer {_layer(target)}")
    if offenders:
        pytest.fail("imports that point up or sideways (see LAYERS):\n"
                    + "\n".join(sorted(offenders)), pytrace=False)


def _third_party(module: str) -> set[str]:
    """Top-level names of the modules imported at module level, outside the package."""
    names = set()
    for node in TREES[module].body:
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names - {PACKAGE, "__future__"} - set(sys.stdlib_module_names)


def test_core_needs_numpy_and_scipy_only():
    offenders = [f"{module} imports {sorted(extra)}" for module in MODULES
                 if _group(module) == "core"
                 and (extra := _third_party(module) - CORE_DEPENDENCIES)]
    assert not offenders, offenders


def test_flat_option_names_stay_in_options_and_apps():
    offenders = [f"{module}:{line} imports {sorted(FLAT_NAMES & set(names))}"
                 for module in MODULES if _group(module) not in ("options", "apps")
                 for line, target, names in _imports(module)
                 if target == f"{PACKAGE}.options" and FLAT_NAMES & set(names)]
    assert not offenders, offenders


def test_modules_are_short():
    long = {module: n for module, path in MODULES.items()
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def _sections() -> set[str]:
    return set(_HEADING.findall(METHOD.read_text())) if METHOD.exists() else set()


def test_method_md_citations_exist():
    sections = _sections()
    assert sections, f"{METHOD} has no numbered sections (headings like '## 1. Title')"
    citing = [*MODULES.values(), ROOT / "README.md",
              *(p for d in ("tests", "benchmarks", "examples") for p in (ROOT / d).rglob("*.py"))]
    missing = [f"{path.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1} cites "
               f"method.md §{m.group(1)}"
               for path in citing if path.exists() for text in [path.read_text()]
               for m in _CITATION.finditer(text) if m.group(1) not in sections]
    if missing:
        pytest.fail(f"citations of sections that docs/method.md does not have (it has "
                    f"{sorted(sections)}):\n" + "\n".join(missing), pytrace=False)


def test_the_checks_see_the_package():
    """The rules above are vacuous if the walk finds nothing: it must see the modules, the
    imports between them, and long functions where they are obviously present."""
    assert {f"{PACKAGE}.core.element", f"{PACKAGE}.matching",
            f"{PACKAGE}.pipeline"} <= set(MODULES)
    assert sum(len(v) for v in _graph().values()) > 10
    assert _cycles({"a": {"b": [1]}, "b": {"a": [2]}, "c": {"a": [3]}}) == [["a", "b"]]
    fn = ast.parse("def f(a, b, *, options=None, **overrides):\n    '''doc'''\n    x = 1\n"
                   "    return x\n").body[0]
    assert _body_lines(fn) == 2 and _options_entry_point("f", fn)
    assert _parameters(fn, False) == ["a", "b", "options", "*overrides"]
    rel = ast.parse("from .modes import _x\nfrom .. import y\n").body
    assert _base(f"{PACKAGE}.element", rel[0]) == f"{PACKAGE}.modes"
    assert _base(PACKAGE, rel[0]) == f"{PACKAGE}.modes"  # a package's level 1 is itself
    assert _base(f"{PACKAGE}.solvers.dense", rel[1]) == PACKAGE
