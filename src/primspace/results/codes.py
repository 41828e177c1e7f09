"""The codes of an experiment's runs, kept beside its summary.

Experiment directories are not kept from one machine to the next; a summary
(:mod:`primspace.results.summary`) keeps the numbers, and this module keeps the codes
the numbers were made from, so that clustering and the claims can be re-checked without
training again: ``primspace summarize DIR --out docs/results/NAME.json`` also writes
``docs/results/NAME.codes.npz`` (:func:`codes_path`), one compressed NumPy archive
(``np.savez_compressed``) holding, for every finished run of the intra grid (and of tune's
tuned runs and the composite grid, which keep the same layout), under its grid key
(``intra/projection-q40-s0``, its folder under ``DIR/runs/``):

``KEY/fit/latents``, ``KEY/infer/latents``
    the fitted codes of the train samples and the inferred codes of the eval samples,
    float32, one row per sample of that phase (``(n, q)``);
``KEY/fit/latents_init``, ``KEY/infer/latents_init``
    the codes each phase started from (e.g. ``P m`` for projection), float32;
``KEY/fit/indices``, ``KEY/infer/indices``
    each phase's samples, int64 positions in the experiment's data set (row ``i`` of the
    codes is sample ``indices[i]``).

A calibrated run (an inference that starts from projection's fit) holds the fit it used.
Besides them: ``runs`` (the keys stored, in order), ``labels`` (int64, one per sample of
the data set), ``label_names`` and ``n_samples`` when the experiment's data file could be
read, and ``primspace_codes_version`` (:data:`CODES_VERSION`), the mark by which
``--overwrite`` recognises an earlier codes file (it never replaces any other file).
:func:`read_codes` reads one back; :func:`codes_in_data_order` puts a run's codes in the
data set's order, as :func:`primspace.experiments.runs.load_codes` does from the directory.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from primspace.utils.errors import OutputExistsError, UserError

__all__ = [
    "CODES_VERSION",
    "VERSION_KEY",
    "CODES_SUFFIX",
    "PHASES",
    "PARTS",
    "codes_path",
    "is_codes_file",
    "check_codes_output",
    "write_codes",
    "read_codes",
    "codes_in_data_order",
]

#: Bumped when the codes file's form changes.
CODES_VERSION = 1
#: The entry that marks a codes file as primspace's (its value: :data:`CODES_VERSION`).
VERSION_KEY = "primspace_codes_version"
#: What replaces a summary's ``.json``: ``NAME.json`` -> ``NAME.codes.npz``.
CODES_SUFFIX = ".codes.npz"
#: The phases of a run, and the arrays stored of each.
PHASES = ("fit", "infer")
PARTS = ("latents", "latents_init", "indices")


def codes_path(summary_path: str | os.PathLike) -> Path:
    """The codes file beside the summary ``summary_path``: ``docs/results/NAME.json`` ->
    ``docs/results/NAME.codes.npz``."""
    return Path(summary_path).with_suffix(CODES_SUFFIX)


def is_codes_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a codes file this module wrote (it holds :data:`VERSION_KEY`)."""
    try:
        with np.load(path, allow_pickle=False) as found:
            return isinstance(found, np.lib.npyio.NpzFile) and VERSION_KEY in found.files
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return False


def check_codes_output(path: str | os.PathLike, overwrite: bool = False, inputs=(), option: str = "--out") -> Path:
    """Refuse to write the codes file ``path``: an existing one without ``overwrite``, and one
    that is not an earlier codes file (:func:`is_codes_file`) even with it; a directory; a path
    that is, holds or lies inside one of ``inputs``. Returns ``path``."""
    from primspace.utils.files import check_outside_inputs
    from primspace.utils.outputs import describe

    path = Path(path)
    check_outside_inputs(path, inputs, option)
    if path.is_dir():
        raise UserError(f"{path}: is a directory, where the codes beside the summary go: choose another {option}")
    if not os.path.lexists(path):
        return path
    if not overwrite:
        raise OutputExistsError(path)
    if path.is_symlink() or not is_codes_file(path):
        what = "a symbolic link" if path.is_symlink() else describe(path)
        raise UserError(
            f"{path}: exists and is {what}; --overwrite replaces only an earlier codes file of primspace "
            f"summarize: choose another {option}"
        )
    return path


def write_codes(path: str | os.PathLike, arrays: dict[str, np.ndarray], overwrite: bool = False) -> Path:
    """Write ``arrays`` (:func:`collect_codes`) to ``path`` compressed, atomically (a temporary
    file renamed into place), checked by :func:`check_codes_output` first."""
    from primspace.utils.files import atomic_path

    if VERSION_KEY not in arrays:
        raise ValueError(f"a codes file holds {VERSION_KEY}")
    path = check_codes_output(path, overwrite)
    with atomic_path(path, overwrite) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return path


def read_codes(path: str | os.PathLike) -> dict:
    """A codes file, read back (one clear line if it is not one).

    Returns
    -------
    dict
        ``runs``: ``{key: {"fit/latents": ..., "fit/latents_init": ..., "fit/indices": ...,
        "infer/...": ...}}`` per run key, in the order stored; ``labels`` (int64 array),
        ``label_names`` (list of str) and ``n_samples`` (int), each None when the data file
        was not readable; ``version``.
    """
    try:
        with np.load(path, allow_pickle=False) as found:
            arrays = {name: found[name] for name in found.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, AttributeError) as exc:
        raise UserError(f"{path}: cannot read the codes ({exc})") from None
    if VERSION_KEY not in arrays or int(arrays[VERSION_KEY]) != CODES_VERSION:
        raise UserError(f"{path}: not a primspace codes file of version {CODES_VERSION}")
    try:
        runs = {
            str(key): {f"{p}/{part}": arrays[f"{key}/{p}/{part}"] for p in PHASES for part in PARTS}
            for key in arrays["runs"]
        }
    except KeyError as exc:
        raise UserError(f"{path}: a damaged codes file (no {exc.args[0]})") from None
    names = arrays.get("label_names")
    return {
        "version": CODES_VERSION,
        "runs": runs,
        "labels": arrays.get("labels"),
        "label_names": None if names is None else [str(n) for n in names],
        "n_samples": int(arrays["n_samples"]) if "n_samples" in arrays else None,
    }


def codes_in_data_order(run: dict, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """One run's codes (a value of :func:`read_codes`'s ``runs``) in the data set's order:
    ``(Z, is_train)``, ``Z`` the fitted codes of the train samples and the inferred codes of
    the eval samples (NaN for samples in neither), as
    :func:`primspace.experiments.runs.load_codes` reads them from the directory."""
    fitted = run["fit/latents"]
    z = np.full((n_samples, *fitted.shape[1:]), np.nan, dtype=np.float32)
    z[run["fit/indices"]] = fitted
    z[run["infer/indices"]] = run["infer/latents"]
    is_train = np.zeros(n_samples, dtype=bool)
    is_train[run["fit/indices"]] = True
    return z, is_train
