"""The layout of an experiment folder ``OUT``: every file name an experiment writes and
the report reads, in one module (the experiments write with it, :mod:`primspace.results`
reads with it).

Files of ``OUT``::

    experiment.json        preset, data file, backend, timings per stage, versions
    data.h5                the simulated data (when no --data was given)
    report.html            the report (primspace.report)
    results/<name>.json    each experiment's numbers (intra, clustering, success, inter,
                           data, appendix_a)
    results/<name>.npz     arrays the figures are drawn from (intra_latent: codes, reconstructions;
                           intra_animation: each primitive's recorded, generated and replayed motion)
    figures/<name>.png     each experiment's figures (figures/animation_<primitive>.gif: animations)
    runs/<key>/            one grid point's run (``result.json`` when finished, ``error.txt``
                           when it failed): ``runs/intra/<init>-q<q>-s<seed>/{fit,infer}``

Besides the names, the words results files use for the codes a clustering row is of
(:data:`LEARNED_CODES`, :data:`INITIAL_CODES`).
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

__all__ = [
    "META_FILE",
    "DATA_FILE",
    "REPORT_FILE",
    "LATENT_RESULTS",
    "ANIMATION_RESULTS",
    "PROBE_RESULTS",
    "IMAGE_STRIPS",
    "LEARNED_CODES",
    "INITIAL_CODES",
    "RESULT_FILE",
    "ERROR_FILE",
    "file_stem",
    "results_file",
    "arrays_file",
    "figures_dir",
    "figure_file",
    "animation_file",
    "run_dir_of",
    "FIT_INIT_OF",
    "fit_init",
    "intra_key",
    "intra_run_dir",
    "phase_dir",
    "fit_point_dir",
]

META_FILE = "experiment.json"
#: The experiment's own data, made when no data file was given.
DATA_FILE = "data.h5"
#: The HTML report (:func:`primspace.report.build_report`).
REPORT_FILE = "report.html"

#: The results (JSON + arrays) the latent-space and reconstruction figures are drawn from.
LATENT_RESULTS = "intra_latent"

#: The results (JSON + arrays) the per-primitive animations are drawn from.
ANIMATION_RESULTS = "intra_animation"

#: The linear probe of the codes (:mod:`primspace.experiments.probe`).
PROBE_RESULTS = "probe"

#: The figure of generated against recorded frames per primitive (drawn with the animations).
IMAGE_STRIPS = "image_strips"

# the "codes" of a latent clustering row: codes after training, or the projection before it
LEARNED_CODES = "learned"
INITIAL_CODES = "initial (P m, untrained)"

#: A finished grid point's result, in its run folder ``OUT/runs/<key>/``.
RESULT_FILE = "result.json"
#: A failed grid point's error, in its run folder.
ERROR_FILE = "error.txt"


# ----------------------------------------------------------------------- files


def results_file(out_dir: str | Path, name: str) -> Path:
    """Where experiment ``name`` keeps its numbers: ``OUT/results/<name>.json``."""
    return Path(out_dir) / "results" / f"{name}.json"


def arrays_file(out_dir: str | Path, name: str) -> Path:
    """Where arrays ``name`` are kept: ``OUT/results/<name>.npz``."""
    return Path(out_dir) / "results" / f"{name}.npz"


def file_stem(name) -> str:
    """``name`` as the stem of a file name: it may come from data (a label, a LeRobot task, a
    primitive's name), so it never reaches a path. Letters, digits, ``-``, ``_`` and ``.``
    are kept, every other character (``/``, NUL, a newline) becomes ``_`` and a leading dot
    too; a name this changed, or longer than 80 characters, is cut to 80 and gets the first
    8 hex digits of its SHA-1, so two names never share a file."""
    text = str(name)
    safe = re.sub(r"^\.", "_", re.sub(r"[^A-Za-z0-9_.-]", "_", text))
    if safe != text or len(safe) > 80:
        digest = hashlib.sha1(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
        safe = f"{safe[:80]}-{digest}"
    return safe


def figures_dir(out_dir: str | Path) -> Path:
    """Where the figures and animations are drawn: ``OUT/figures``."""
    return Path(out_dir) / "figures"


def figure_file(out_dir: str | Path, name: str) -> Path:
    """Where figure ``name`` is drawn: ``OUT/figures/<name>.png`` (:func:`file_stem` of ``name``)."""
    return figures_dir(out_dir) / f"{file_stem(name)}.png"


def animation_file(out_dir: str | Path, name: str) -> Path:
    """Where the animation of ``name`` (a primitive) is drawn: ``OUT/figures/animation_<name>.gif``
    (:func:`file_stem` of ``name``)."""
    return figures_dir(out_dir) / f"animation_{file_stem(name)}.gif"


# ------------------------------------------------------------------------ runs


def run_dir_of(out_dir: str | Path, key: str) -> Path:
    """The run folder of grid point ``key``: ``OUT/runs/<key>``."""
    return Path(out_dir) / "runs" / key


#: Starts whose grid point infers with another init's fit.
FIT_INIT_OF = {"calibrated": "projection"}


def fit_init(init: str) -> str:
    """The init of the fit an init's grid point uses (itself, or :data:`FIT_INIT_OF`'s)."""
    return FIT_INIT_OF.get(init, init)


def intra_key(init: str, latent_dim: int, seed: int) -> str:
    """The grid key (and ``OUT/runs/`` folder) of one intra-primitive run."""
    return f"intra/{init}-q{latent_dim}-s{seed}"


def intra_run_dir(out_dir: str | Path, init: str, latent_dim: int, seed: int) -> Path:
    """``OUT/runs/intra/<init>-q<q>-s<seed>``: its ``fit/`` and ``infer/`` run directories."""
    return run_dir_of(out_dir, intra_key(init, latent_dim, seed))


def phase_dir(out_dir: str | Path, init: str, latent_dim: int, seed: int, phase: str) -> Path:
    """The ``fit`` or ``infer`` run directory of an intra grid point (a calibrated point's
    ``fit`` is its projection point's)."""
    return intra_run_dir(out_dir, fit_init(init) if phase == "fit" else init, latent_dim, seed) / phase


def fit_point_dir(run_dir: Path, init: str) -> Path:
    """The grid point whose fit the point ``run_dir`` (of ``init``) uses: itself, or the sibling
    of :func:`fit_init` (grid keys start with their init: ``calibrated-q40-s0`` ->
    ``projection-q40-s0``, ``calibrated-fold3-s0`` -> ``projection-fold3-s0``)."""
    if not run_dir.name.startswith(init):
        raise ValueError(f"grid point {run_dir.name} is not one of init {init}")
    return run_dir.with_name(fit_init(init) + run_dir.name[len(init) :])
