"""Gathering the codes of an experiment directory's runs into the codes file kept beside
its summary (:mod:`primspace.results.codes` names the file's form and reads it back):
``primspace summarize DIR --out docs/results/NAME.json`` writes both
(:func:`write_summary_with_codes`)."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from primspace.results.codes import CODES_VERSION, PHASES, VERSION_KEY, check_codes_output, codes_path, write_codes
from primspace.results.layout import fit_point_dir, intra_key, run_dir_of
from primspace.results.readers import read_meta, read_results
from primspace.utils.errors import UserError

__all__ = ["stored_runs", "collect_codes", "write_run_codes", "write_summary_with_codes"]

log = logging.getLogger(__name__)


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


def write_run_codes(path: str | os.PathLike, out_dir: str | os.PathLike, overwrite: bool = False) -> dict:
    """Write the codes of experiment directory ``out_dir``'s runs to ``path``; return what a
    summary says of them: ``file`` (``path``'s name: the summary's neighbour), ``runs`` (the
    number stored) and ``missing`` (the keys of listed runs whose folders were unreadable)."""
    check_codes_output(path, overwrite, inputs=(out_dir,))  # refused before any run is read
    arrays, missing = collect_codes(out_dir)
    write_codes(path, arrays, overwrite)
    return {"file": Path(path).name, "runs": len(arrays["runs"]), "missing": missing}


def write_summary_with_codes(path: str | Path, summary: dict, directory: str | Path, overwrite: bool = False) -> dict:
    """What ``primspace summarize`` writes: the codes of ``directory``'s runs beside the
    summary ``path`` (:func:`write_run_codes`), then the summary with its ``codes`` field
    naming them (:func:`primspace.results.summary.write_summary`). A summary that cannot
    be written is refused before its codes are; returns the summary written."""
    from primspace.results.summary import write_summary
    from primspace.utils.files import check_output

    check_output(path, overwrite)
    codes = write_run_codes(codes_path(path), directory, overwrite)
    return write_summary(path, summary | {"codes": codes}, overwrite=overwrite)
