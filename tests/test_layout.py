"""The package's shape (issue 12), checked on the source so it stays that way.

- no module in ``src/primspace`` over 500 lines; no function over 60 lines of code
  (its docstring not counted: numpy-style parameter lists are documentation, not
  length) unless its docstring says why it is long;
- no star imports;
- layers import downwards only (docs/architecture.md): data and the simulator know
  nothing of models; training knows nothing of experiments; figures know nothing of
  training; experiments know nothing of the report; nothing imports the command line.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import primspace

SRC = Path(primspace.__file__).resolve().parent
MODULES = sorted(SRC.rglob("*.py"))
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 60

# package (or module) -> what it may never import
FORBIDDEN = {
    "data": ("sim", "latent", "model", "model_config", "train", "cluster", "plots", "experiments", "report", "demo", "cli"),
    "sim": ("latent", "model", "model_config", "train", "cluster", "plots", "experiments", "report", "demo", "cli"),
    "cluster": ("sim", "latent", "model", "train", "experiments", "report", "demo", "cli"),
    "probe": ("sim", "latent", "model", "train", "experiments", "report", "demo", "cli"),
    # the segmentation package: the windows method, scores, results, peers (ruptures, hmmlearn) and
    # upper bounds (classifiers given the labels) see motion arrays and codes only ...
    "segmentation": ("sim", "latent", "model", "train", "experiments", "report", "demo", "cli"),
    # ... the methods of a single-primitive model decode a trained run (train)
    "segmentation.synthesis": ("sim", "experiments", "report", "demo", "cli"),
    "segmentation.surprise": ("sim", "experiments", "report", "demo", "cli"),
    "segmentation.inferred": ("sim", "experiments", "report", "demo", "cli"),
    # the peers of prediction (ProMP, nearest neighbour, mean motion): they see motion arrays only
    "peers": ("sim", "latent", "model", "train", "cluster", "experiments", "report", "demo", "cli"),
    "model_config": ("model", "latent", "train", "sim", "cluster", "plots", "experiments", "report", "demo", "cli"),
    "model": ("latent", "train", "sim", "cluster", "plots", "experiments", "report", "demo", "cli"),
    "latent": ("model", "train", "sim", "cluster", "plots", "experiments", "report", "demo", "cli"),
    "train": ("sim", "cluster", "plots", "experiments", "report", "demo", "cli"),
    "plots": ("train", "model", "latent", "experiments", "report", "demo", "cli"),
    # the scene-only prediction: above train and cluster (it uses both), below the experiments
    "scene": ("experiments", "report", "demo", "cli"),
    "experiments": ("report", "demo", "cli"),
    "report": ("demo", "cli"),
    "demo": ("cli",),
    # small statistics helpers: the standard library only
    "stats": ("data", "sim", "cluster", "probe", "segmentation",
              "model_config", "model", "latent", "train", "plots", "experiments", "report", "demo", "cli", "docs"),
    # the docs' generated numbers: read from stored summaries, above the experiments and the report
    "docs": ("cli",),
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
        lines = node.end_lineno - node.lineno + 1
        doc = ast.get_docstring(node)
        if doc is not None:
            first = node.body[0]
            lines -= first.end_lineno - first.lineno + 1
        if lines > MAX_FUNCTION_LINES:
            assert doc and "long" in doc.lower(), f"{path.name}:{node.lineno} {node.name}: {lines} lines of code"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(SRC)))
def test_no_star_imports_and_layers_import_downwards(path):
    module = _name(path)
    forbidden = FORBIDDEN.get(_layer(f"primspace.{module}"), ())
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom):
            assert all(a.name != "*" for a in node.names), f"{module}: star import from {node.module}"
            names = [node.module or ""]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        for imported in names:
            if imported.startswith("primspace."):
                assert _top(imported) not in forbidden, f"primspace.{module} imports {imported}"


def test_the_layer_table_names_real_packages():
    """A renamed package must not silently drop out of the layering check."""
    tops = {_top(f"primspace.{_name(p)}") for p in MODULES}
    names = {".".join(_name(p).split(".")[:2]) for p in MODULES}
    for layer, forbidden in FORBIDDEN.items():
        assert (layer in tops or layer in names) and set(forbidden) <= tops, (layer, set(forbidden) - tops)
