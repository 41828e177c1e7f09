"""Reading an experiment folder's results: its description (``experiment.json``), each
experiment's numbers (``results/<name>.json``) and arrays (``results/<name>.npz``), from
the folder's own files only (:mod:`primspace.results.layout` names them)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from primspace.results.layout import META_FILE, arrays_file, results_file
from primspace.utils.errors import UserError, first_line

__all__ = ["read_results", "read_arrays", "read_meta"]


def _read_json(path: Path, what: str) -> Any:
    if path.is_symlink() or (path.exists() and not path.is_file()):
        # an experiment folder's results are its own files: a link could put any readable file into a report
        raise UserError(
            f"{path}: not a regular file (a link or something else); {what} are read from the "
            "experiment folder's own files only"
        )
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise UserError(f"{path}: cannot read {what} ({first_line(exc)})") from None


def read_results(out_dir: str | Path, name: str) -> Any | None:
    """The results of experiment ``name`` in ``out_dir``, or None if it has not run."""
    path = results_file(out_dir, name)
    if not path.exists():
        return None
    results = _read_json(path, "the results")
    if not isinstance(results, dict):
        raise UserError(f"{path}: not a results file (a JSON object was expected)")
    return results


def read_arrays(out_dir: str | Path, name: str) -> dict[str, np.ndarray] | None:
    """The arrays ``OUT/results/<name>.npz`` as a dict, or None if they were not written."""
    path = arrays_file(out_dir, name)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {key: npz[key] for key in npz.files}
    except (OSError, ValueError) as exc:
        raise UserError(f"{path}: cannot read the arrays ({first_line(exc)})") from None


def read_meta(out_dir: str | Path) -> dict:
    """``OUT/experiment.json``: preset, settings, data file, timings, failures."""
    meta = _read_json(Path(out_dir) / META_FILE, "the experiment description")
    if not isinstance(meta, dict):
        raise UserError(f"{Path(out_dir) / META_FILE}: not an experiment description (a JSON object was expected)")
    return meta
