"""Build primspace's API reference from its docstrings: ``python docs/build_api.py [OUT]``.

``make docs`` runs it (OUT: ``build/api``; open ``build/api/index.html``). Every module of
the installed ``primspace`` package is documented, found by walking the package (so a
module added or moved needs no change here), with pdoc (the ``test`` extra installs it; no search index, to keep it small)
reading numpydoc docstrings. Nothing is downloaded: pdoc renders offline, and
tests/test_api_docs.py builds the reference into a temporary folder in CI. A module whose
optional dependency is missing (ray, av, movement-primitives) is left out with a warning
instead of failing the build.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import sys
import warnings
from pathlib import Path

os.environ.setdefault("PDOC_ALLOW_EXEC", "1")  # importing mujoco and torch runs `uname`; allowed, not warned about

import pdoc  # noqa: E402
import pdoc.render  # noqa: E402

import primspace  # noqa: E402

#: Modules not documented: entry points that only run something.
SKIP = ("primspace.__main__",)


def modules() -> list[str]:
    """Every module of the primspace package that imports, by name, sorted (the package
    itself first); one that does not is named in a warning on stderr and left out."""
    names = ["primspace"]
    for info in pkgutil.walk_packages(primspace.__path__, "primspace.", onerror=lambda name: None):
        if info.name in SKIP or info.name.rsplit(".", 1)[-1].startswith("_"):
            continue
        try:
            importlib.import_module(info.name)
        except Exception as e:  # an optional dependency missing: the rest is still documented
            print(f"warning: {info.name} left out of the API reference: {type(e).__name__}: {e}", file=sys.stderr)
            continue
        names.append(info.name)
    return sorted(names)


def build(out: Path) -> Path:
    """Write the reference into ``out``; return its ``index.html``."""
    pdoc.render.configure(
        docformat="numpy", search=False, show_source=False, footer_text=f"primspace {primspace.__version__}"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        # each package's submodules are named here too (so a broken one is left out alone): not a mistake
        warnings.filterwarnings("ignore", message="The module specification", category=UserWarning)
        pdoc.pdoc(*modules(), output_directory=Path(out))
    return Path(out) / "index.html"


if __name__ == "__main__":
    index = build(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("build") / "api")
    print(f"API reference: {index}")
