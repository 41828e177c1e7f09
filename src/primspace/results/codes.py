"""The codes of an experiment's runs, kept beside its summary.

Experiment directories are not kept from one machine to the next; a summary
(:mod:`primspace.experiments.summary`) keeps the numbers, and this module keeps the codes
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

import logging
import os
import zipfile
from pathlib import Path

import numpy as np

from primspace.utils.errors import OutputExistsError, UserError
from primspace.experiments.results import read_meta, read_results
from primspace.experiments.runs import fit_point_dir, intra_key
from primspace.experiments.sweep import run_dir_of

__all__ = [
    "CODES_VERSION",
    "VERSION_KEY",
    "CODES_SUFFIX",
    "PHASES",
    "PARTS",
    "codes_path",
    "stored_runs",
    "collect_codes",
    "is_codes_file",
    "check_codes_output",
    "write_codes",
    "write_run_codes",
    "read_codes",
    "codes_in_data_order",
    "write_summary_with_codes",
]

log = logging.getLogger(__name__)

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


def stored_runs(out_dir: str | os.PathLike) -> list[tuple[str, str]]:
    """``(key, init)`` of every finished run whose codes are kept, in order, each once: the
    intra grid's, tune's tuned runs (those it reran; the others are intra's), the composite
    grid's."""
    intra = read_results(out_dir, "intra") or {}
    tuned = (read_results(out_dir, "tune") or {}).get("tuned", {})
    composite = read_results(out_dir, "composite") or {}
    listed = [
        (r.get("key") or intra_key(r["init"], r["latent_dim"], r["seed"]), r["init"]) for r in intra.get("runs", [])
    ]
    listed += [
        (r.get("key") or f"tuned/{r['init']}-q{r['latent_dim']}-s{r['seed']}", r["init"]) for r in tuned.get("runs", [])
    ]
    listed += [(r["key"], r["init"]) for r in composite.get("runs", []) if r.get("key")]
    return list(dict.fromkeys(listed))


def _run_arrays(out_dir: str | os.PathLike, key: str, init: str) -> dict[str, np.ndarray]:
    """The stored arrays of one run (names without the key); UserError if a phase cannot be read."""
    from primspace.train import load_run

    run_dir = run_dir_of(out_dir, key)
    arrays = {}
    for phase, where in zip(PHASES, (fit_point_dir(run_dir, init) / "fit", run_dir / "infer")):
        run = load_run(where)
        arrays[f"{phase}/latents"] = np.asarray(run.latents, dtype=np.float32)
        arrays[f"{phase}/latents_init"] = np.asarray(run.initial_latents, dtype=np.float32)
        arrays[f"{phase}/indices"] = np.asarray(run.indices, dtype=np.int64)
    return arrays


def _data_arrays(out_dir: str | os.PathLike) -> dict[str, np.ndarray]:
    """``labels``, ``label_names`` and ``n_samples`` of the experiment's data file (those it
    has), or nothing when the file is gone or unreadable."""
    from primspace.data import MotionDataset

    where = read_meta(out_dir).get("data")
    try:
        data = MotionDataset.load(where)
    except (UserError, OSError, TypeError) as exc:
        log.warning("%s: the data file %s cannot be read, no labels kept with the codes (%s)", out_dir, where, exc)
        return {}
    arrays = {"n_samples": np.int64(len(data))}
    if data.labels is not None:
        arrays["labels"] = np.asarray(data.labels, dtype=np.int64)
    if data.label_names is not None:
        arrays["label_names"] = np.asarray([str(n) for n in data.label_names], dtype=str)
    return arrays


def collect_codes(out_dir: str | os.PathLike) -> tuple[dict[str, np.ndarray], list[str]]:
    """The arrays of the codes file of experiment directory ``out_dir`` (see the module), and
    the keys of the runs its results list whose folders could not be read (not stored)."""
    arrays: dict[str, np.ndarray] = {VERSION_KEY: np.int64(CODES_VERSION)}
    keys, missing = [], []
    for key, init in stored_runs(out_dir):
        try:
            found = _run_arrays(out_dir, key, init)
        except (UserError, ValueError) as exc:
            log.warning("%s: its codes are not kept (%s)", key, exc)
            missing.append(key)
            continue
        arrays |= {f"{key}/{name}": value for name, value in found.items()}
        keys.append(key)
    arrays["runs"] = np.asarray(keys, dtype=str)
    return arrays | _data_arrays(out_dir), missing


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


def write_run_codes(path: str | os.PathLike, out_dir: str | os.PathLike, overwrite: bool = False) -> dict:
    """Write the codes of experiment directory ``out_dir``'s runs to ``path``; return what a
    summary says of them: ``file`` (``path``'s name: the summary's neighbour), ``runs`` (the
    number stored) and ``missing`` (the keys of listed runs whose folders were unreadable)."""
    check_codes_output(path, overwrite, inputs=(out_dir,))  # refused before any run is read
    arrays, missing = collect_codes(out_dir)
    write_codes(path, arrays, overwrite)
    return {"file": Path(path).name, "runs": len(arrays["runs"]), "missing": missing}


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


def write_summary_with_codes(path: str | Path, summary: dict, directory: str | Path, overwrite: bool = False) -> dict:
    """What ``primspace summarize`` writes: the codes of ``directory``'s runs beside the
    summary ``path`` (:func:`write_run_codes`), then the summary with its ``codes`` field
    naming them (:func:`primspace.experiments.summary.write_summary`). A summary that cannot
    be written is refused before its codes are; returns the summary written."""
    from primspace.experiments.summary import write_summary
    from primspace.utils.files import check_output

    check_output(path, overwrite)
    codes = write_run_codes(codes_path(path), directory, overwrite)
    return write_summary(path, summary | {"codes": codes}, overwrite=overwrite)
