"""The package's shape (issue 12), checked on the source so it stays that way.

- no module in ``src/primspace`` over 500 lines; no function body over 60 lines of code
  (its docstring not counted: numpy-style parameter lists are documentation, not
  length) unless its docstring says why it is long;
- no star imports;
- layers import downwards only (docs/architecture.md): data and the simulator know
  nothing of models; training knows nothing of prediction or experiments; figures know
  nothing of training; experiments know nothing of the report; nothing imports the
  command line;
- no import cycle among primspace's modules (issue 37), and no private name (``_x``)
  imported from another module.

Imports are read from the source (``ast``): function-level imports and those under
``TYPE_CHECKING`` count; relative imports (``from ..train import fit``) are resolved. A
name imported from a package resolves to the module that provides it: its submodule
(``from primspace.experiments import figures``), the module its ``__init__`` imports the
name from (``from primspace.data import MotionDataset`` -> ``primspace.data.dataset``; a
name the package forwards lazily too, ``primspace.train.fit`` -> ``primspace.train.api``),
else the package itself. A package's ``__init__`` depends on what it imports when it is
imported; its lazy forwards (in functions, under ``TYPE_CHECKING``) are its names'
dependencies, not its own.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import NamedTuple

import pytest

import primspace

SRC = Path(primspace.__file__).resolve().parent
MODULES = sorted(SRC.rglob("*.py"))
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 60

#: Every floor above ``utils``: it imports none of them.
ABOVE_UTILS = (
    "data",
    "sim",
    "cluster",
    "probe",
    "segmentation",
    "model",
    "train",
    "predict",
    "estimator",
    "plots",
    "act",
    "results",
    "experiments",
    "report",
    "demo",
    "cli",
)

# package (or module) -> what it may never import
FORBIDDEN = {
    # the floor everyone stands on: errors, files, output marks and folders, seeds, progress, statistics
    "utils": ABOVE_UTILS,
    "data": (
        "sim",
        "model",
        "train",
        "predict",
        "cluster",
        "plots",
        "act",
        "results",
        "experiments",
        "report",
        "demo",
        "cli",
    ),
    "sim": ("model", "train", "predict", "cluster", "plots", "act", "results", "experiments", "report", "demo", "cli"),
    "cluster": ("sim", "model", "train", "predict", "act", "results", "experiments", "report", "demo", "cli"),
    "probe": ("sim", "model", "train", "predict", "act", "results", "experiments", "report", "demo", "cli"),
    # the segmentation package: the windows method, scores, results, peers (ruptures, hmmlearn) and
    # upper bounds (classifiers given the labels) see motion arrays and codes only ...
    "segmentation": ("sim", "model", "train", "predict", "act", "results", "experiments", "report", "demo", "cli"),
    # ... the methods of a single-primitive model decode a trained run (train)
    "segmentation.synthesis": ("sim", "act", "results", "experiments", "report", "demo", "cli"),
    "segmentation.surprise": ("sim", "act", "results", "experiments", "report", "demo", "cli"),
    "segmentation.inferred": ("sim", "act", "results", "experiments", "report", "demo", "cli"),
    # the model: its config (torch-free), the decoder, the codes and their starts, the calibration
    "model": ("train", "predict", "sim", "cluster", "plots", "act", "results", "experiments", "report", "demo", "cli"),
    "train": ("sim", "cluster", "predict", "plots", "act", "results", "experiments", "report", "demo", "cli"),
    # prediction from a beginning: one floor above train (and cluster: primitives as clusters of codes)
    "predict": ("sim", "plots", "act", "results", "experiments", "report", "demo", "cli"),
    # the estimator (AutoDecoder) sits above train and predict, below the experiments
    "estimator": ("sim", "act", "results", "experiments", "report", "demo", "cli"),
    "plots": ("train", "predict", "model", "act", "results", "experiments", "report", "demo", "cli"),
    # acting: plans from the scene executed in the simulator (sim), below the experiments
    "act": ("results", "experiments", "report", "demo", "cli"),
    # reading an experiment folder's results (its layout, readers, tables, the claims): JSON and arrays
    # only, below the experiments that write them and the report that prints them
    "results": tuple(f for f in ABOVE_UTILS if f not in ("data", "results")),
    "experiments": ("report", "demo", "cli"),
    # the report reads results only: no experiment
    "report": ("experiments", "demo", "cli"),
    "demo": ("cli",),
}


def _name(path: Path) -> str:
    rel = path.relative_to(SRC).with_suffix("")
    return ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)


def _top(module: str) -> str:
    """``primspace.train.api`` -> ``train``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _layer(module: str) -> str:
    """The most specific row of :data:`FORBIDDEN` for a module: ``primspace.segmentation.synthesis``
    -> ``segmentation.synthesis`` where the table has it, else its package (``segmentation``)."""
    parts = module.split(".")
    two = ".".join(parts[1:3])
    return two if two in FORBIDDEN else _top(module)


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_module_size_and_function_length(path):
    text = path.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= MAX_MODULE_LINES, f"{path.name}: {len(text.splitlines())} lines"
    for node in ast.walk(_tree(path)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        doc = ast.get_docstring(node)
        body = node.body[1:] if doc is not None and len(node.body) > 1 else node.body
        lines = node.end_lineno - body[0].lineno + 1  # the body: the signature declares, the docstring documents
        if lines > MAX_FUNCTION_LINES:
            assert doc and "long" in doc.lower(), f"{path.name}:{node.lineno} {node.name}: {lines} lines of code"


# ------------------------------------------------------------------------ the import graph

#: Every module of primspace by its full name (``primspace.train.api``; a package by its own).
PATHS = {f"primspace.{_name(p)}".rstrip("."): p for p in MODULES}


class Import(NamedTuple):
    """One import of a primspace module, as written (relative imports resolved)."""

    module: str  # the importing module
    line: int
    named: str  # the module it names: ``primspace.train`` for ``from ..train import fit``
    name: str | None  # the name imported from it; None for ``import primspace.x``
    eager: bool  # run when ``module`` is imported (not in a function, not under TYPE_CHECKING)
    bound: str | None = None  # the name it binds in ``module`` (``as`` ...), for a from-import


def _nodes(node: ast.AST, eager: bool = True):
    """Every import statement under ``node``, with whether it runs at import time."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            yield child, eager
        deferred = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) or (
            isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test)
        )
        yield from _nodes(child, eager and not deferred)


def _imports_in(module: str, tree: ast.Module) -> list[Import]:
    """The imports of primspace modules in ``tree``, the source of ``module`` (star imports: name ``*``)."""
    package = module if PATHS[module].name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node, eager in _nodes(tree):
        if isinstance(node, ast.Import):
            out += [Import(module, node.lineno, a.name, None, eager) for a in node.names]
            continue
        named = node.module or ""
        if node.level:  # from . import x, from ..train import fit
            parts = package.split(".")[: len(package.split(".")) - node.level + 1]
            named = ".".join(parts + ([named] if named else []))
        out += [Import(module, node.lineno, named, a.name, eager, a.asname or a.name) for a in node.names]
    return [i for i in out if i.named == "primspace" or i.named.startswith("primspace.")]


IMPORTS = {m: _imports_in(m, _tree(p)) for m, p in PATHS.items()}


def _provided() -> dict[str, dict[str, tuple[str, str]]]:
    """Per package: the names its ``__init__`` imports, each with the module and name it is imported as."""
    out = {}
    for module, path in PATHS.items():
        if path.name == "__init__.py":
            out[module] = {i.bound: (i.named, i.name) for i in IMPORTS[module] if i.name not in (None, "*")}
    return out


PROVIDED = _provided()


def _target(imp: Import) -> str | None:
    """The module ``imp`` depends on (module docstring); None when it names no module."""
    module, name, seen = imp.named, imp.name, set()
    while module in PATHS and name not in (None, "*") and f"{module}.{name}" not in PATHS:
        if name not in PROVIDED.get(module, {}) or module in seen:
            return module  # a name the module defines itself
        seen.add(module)
        module, name = PROVIDED[module][name]
    if module in PATHS and name not in (None, "*") and f"{module}.{name}" in PATHS:
        return f"{module}.{name}"
    return module if module in PATHS else None


def _edges() -> dict[str, dict[str, Import]]:
    """module -> {module it depends on: the first import that says so}."""
    edges: dict[str, dict[str, Import]] = {m: {} for m in PATHS}
    for module, imports in IMPORTS.items():
        forwards = PATHS[module].name == "__init__.py"  # a package's lazy imports are its names'
        for imp in imports:
            target = _target(imp)
            if target is not None and target != module and (imp.eager or not forwards):
                edges[module].setdefault(target, imp)
    return edges


def _cycles(edges: dict[str, dict]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(edges[root]))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(edges[child])))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_no_star_imports_and_layers_import_downwards(path):
    module = f"primspace.{_name(path)}".rstrip(".")
    forbidden = FORBIDDEN.get(_layer(module), ())
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom):
            assert all(a.name != "*" for a in node.names), f"{module}: star import from {node.module}"
    for imp in IMPORTS[module]:  # the package named and the module that provides the name
        for imported in {imp.named, _target(imp) or imp.named}:
            assert _top(imported) not in forbidden, f"{module}:{imp.line} imports {imported}"


def test_every_import_names_a_module_that_exists():
    """A lazy import of a moved or deleted module fails only when its function runs."""
    missing = [f"{i.module}:{i.line} {i.named}" for imports in IMPORTS.values() for i in imports if _target(i) is None]
    assert not missing, "imports of no module:\n" + "\n".join(missing)


def test_no_import_cycles():
    """No module depends on itself through others (issue 37): each cycle with its imports."""
    edges = _edges()
    report = []
    for component in _cycles(edges):
        inside = set(component)
        report.append(
            "cycle:\n"
            + "\n".join(f"  {i.module}:{i.line} -> {t}" for m in component for t, i in edges[m].items() if t in inside)
        )
    assert not report, f"{len(report)} import cycle(s):\n" + "\n".join(report)


def test_no_private_name_is_imported_from_another_module():
    """A name with a leading underscore is its module's own: shared helpers get public names."""
    private = [
        f"{i.module}:{i.line} from {i.named} import {i.name}"
        for imports in IMPORTS.values()
        for i in imports
        if i.name and i.name.startswith("_") and not i.name.endswith("__") and _target(i) != i.module
    ]
    assert not private, "private names imported from another module:\n" + "\n".join(private)


def test_the_import_graph_sees_every_form():
    """The reader resolves relative imports, ``import primspace.x`` and a package's forwarded names."""

    def target(module: str, source: str) -> str | None:
        return _target(_imports_in(module, ast.parse(source))[0])

    assert target("primspace.predict.api", "from ..train import fit") == "primspace.train.api"
    assert target("primspace.predict.api", "from . import base") == "primspace.predict.base"
    assert target("primspace.data.dataset", "from .storage import read_fields") == "primspace.data.storage"
    assert target("primspace.experiments.intra", "import primspace.sim") == "primspace.sim"
    assert target("primspace.experiments.intra", "from primspace.data import MotionDataset") == "primspace.data.dataset"
    assert target("primspace.cli.app", "from primspace import __version__") == "primspace"
    assert target("primspace.cli.app", "from primspace.nowhere import x") is None
    assert {"primspace.data.storage", "primspace.utils.files"} <= set(_edges()["primspace.data.dataset"]) | set(
        _edges()["primspace.data.storage"]
    )
    assert _cycles({"a": {"b": 0}, "b": {"c": 0}, "c": {"a": 0}, "d": {"a": 0}}) == [["a", "b", "c"]]


def test_the_layer_table_names_real_packages():
    """A renamed package must not silently drop out of the layering check."""
    tops = {_top(f"primspace.{_name(p)}") for p in MODULES}
    names = {".".join(_name(p).split(".")[:2]) for p in MODULES}
    for layer, forbidden in FORBIDDEN.items():
        assert (layer in tops or layer in names) and set(forbidden) <= tops, (layer, set(forbidden) - tops)


def test_the_model_config_and_the_command_line_defaults_load_without_torch():
    """``primspace.model.config`` (and the ``model`` package) is torch-free: configs and CLI defaults load fast."""
    import subprocess
    import sys

    code = "import sys, primspace.model.config; assert 'torch' not in sys.modules, 'torch imported'"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
