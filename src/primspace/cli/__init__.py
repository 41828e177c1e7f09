"""The ``primspace`` command.

Each command parses its flags and calls the library; the work lives in the modules. One
module per group of commands registers them on :data:`primspace.cli.app.app`.
"""

# imported for their side effect, in the order `primspace --help` lists the commands
from primspace.cli import importing  # noqa: F401, I001
from primspace.cli import data  # noqa: F401
from primspace.cli import cluster  # noqa: F401
from primspace.cli import segment  # noqa: F401
from primspace.cli import train  # noqa: F401
from primspace.cli import animate  # noqa: F401
from primspace.cli import predict  # noqa: F401
from primspace.cli import fit_predictor  # noqa: F401
from primspace.cli import act  # noqa: F401
from primspace.cli import experiments  # noqa: F401
from primspace.cli import diagnose  # noqa: F401
from primspace.cli.app import app, main

__all__ = ["app", "main"]
