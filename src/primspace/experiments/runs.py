"""What the experiments share about their runs: keys, configurations, data, codes.

Every experiment (intra, clustering, success, inter) builds on the intra-primitive
grid's runs ``OUT/runs/intra/<init>-q<q>-s<seed>/{fit,infer}``; this module names them,
derives each run's configurations from the preset, loads a run's data and scaler, and
reads the codes back (the runs' folders are named in :mod:`primspace.results.layout`).
It imports no experiment.

An inference start that needs a trained run (``calibrated``) has no fit of its own: its
point infers with the fit of the init it calibrates (:data:`FIT_INIT_OF`), e.g.
``intra/calibrated-q40-s0/infer`` from ``intra/projection-q40-s0/fit``. Both points
resume that fit under one lock, so whichever starts first trains it and the other waits.

A grid point's runs are the keyword arguments of :func:`primspace.train.fit` and
:func:`primspace.train.infer` that :func:`point_jobs` builds: :func:`fit_and_infer` runs
them one after the other, and :func:`pack_grid_runs` trains the unfinished ones of many
points packed on one device (:mod:`primspace.train.packed`) before the grid, which then
finds them finished.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.presets import ExperimentPreset
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import FIT_INIT_OF, RESULT_FILE, fit_init, fit_point_dir, phase_dir
from primspace.utils.errors import UserError

__all__ = [
    "fit_lock",
    "shared_fit",
    "shared_fits_last",
    "train_configs",
    "load_run_data",
    "experiment_scaler",
    "curves",
    "focus_runs",
    "load_codes",
    "initial_codes",
    "all_frame_losses",
    "psnr",
    "point_jobs",
    "fit_and_infer",
    "pack_grid_runs",
]

log = logging.getLogger(__name__)


def shared_fits_last(points: list) -> list:
    """Grid points in the order to run them: those that infer with another point's fit
    (:data:`FIT_INIT_OF`; keys ``<experiment>/<init>-...``) after the others, so no worker
    waits on a fit in progress."""
    return sorted(points, key=lambda p: p.key.split("/", 1)[-1].split("-", 1)[0] in FIT_INIT_OF)


def fit_lock(fit_dir: Path):
    """The lock (a context manager) beside ``fit_dir`` that grid points sharing a fit
    (:data:`FIT_INIT_OF`) hold while they resume it, so they train it once."""
    from primspace.utils.files import exclusive_lock

    return exclusive_lock(fit_dir.parent / f".{fit_dir.name}.lock")


def shared_fit(fit_dir: Path, **fit_args):
    """:func:`primspace.train.fit` into ``fit_dir`` with ``resume=True``, holding
    :func:`fit_lock`: grid points that share a fit (:data:`FIT_INIT_OF`) train it once."""
    from primspace.train import fit

    with fit_lock(fit_dir):
        return fit(resume=True, out_dir=fit_dir, **fit_args)


def train_configs(preset: ExperimentPreset, latent_dim: int, seed: int, epochs: int):
    """The model and train configurations of one run: the preset's, with the run's q, seed
    and epochs (a checkpoint every tenth of them).

    Returns
    -------
    (ModelConfig, TrainConfig)
    """
    model_config = replace(preset.model, latent_dim=latent_dim)
    train_config = replace(preset.train, epochs=epochs, seed=seed, checkpoint_every=max(1, epochs // 10))
    return model_config, train_config


def load_run_data(data_path: str, preset: ExperimentPreset) -> tuple[MotionDataset, bool]:
    """The data set of a grid run, and whether it trains the vision loss (images then in memory)."""
    data = MotionDataset.load(data_path)
    use_images = preset.images and data.has_images
    return (data.load_images() if use_images else data), use_images


def experiment_scaler(data: MotionDataset):
    """The joint scaler of every run of an experiment: fitted over all of its motions.

    The paper (Motion Capture Data): "for each joint angle all the values in all
    sequences were normalized to be in [-1, 1] interval". Fitting it on the part a run
    trains on would leave the other part's targets outside [-1, 1] (about 3%
    of intra's evaluation values), and in the inter-primitive fold that holds out
    grasp, whose finger joints never move in phase 1, grasp's finger targets would stay
    in metres (|y| <= 0.04, 1/2500 of their weight). Every experiment run therefore
    scales with the extremes of the whole data set it was given.
    """
    from primspace.data import JointScaler

    return JointScaler().fit(data.motor)


def curves(history: list[dict]) -> list[dict]:
    """The per-epoch losses of a run (its metrics.jsonl without timings)."""
    return [{k: h.get(k) for k in ("epoch", "loss", "motor", "vision")} for h in history]


def focus_runs(exp: ExperimentDir, results: dict) -> tuple[int, int, list[str]]:
    """(q, seed, inits) of the finished intra runs that clustering, success and the latent
    figures use: the preset's ``cluster_latent_dim`` (else the largest q), the first seed."""
    preset = exp.preset
    q = preset.cluster_latent_dim if preset.cluster_latent_dim in preset.latent_dims else max(preset.latent_dims)
    seed = preset.seeds[0]
    done = {(r["init"], r["latent_dim"], r["seed"]) for r in results["runs"]}
    return q, seed, [i for i in preset.inits if (i, q, seed) in done]


def load_codes(exp: ExperimentDir, init: str, latent_dim: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """All samples' codes of one intra run, in data-set order, and a mask of the train part.

    Returns ``(Z, is_train)``: ``Z`` (N, q) with the fitted codes of the train samples
    and the inferred codes of the eval samples.
    """
    from primspace.train import load_run

    fitted, inferred = (load_run(phase_dir(exp.path, init, latent_dim, seed, p)) for p in ("fit", "infer"))
    n = len(exp.dataset())
    z = np.full((n, latent_dim), np.nan, dtype=np.float32)
    z[fitted.indices] = fitted.latents
    z[inferred.indices] = inferred.latents
    is_train = np.zeros(n, dtype=bool)
    is_train[fitted.indices] = True
    return z, is_train


def initial_codes(exp: ExperimentDir, init: str, latent_dim: int, seed: int) -> np.ndarray:
    """All samples' codes of one intra run *before* training (e.g. ``P m``), float64, data-set order."""
    from primspace.train import load_run

    fitted, inferred = (load_run(phase_dir(exp.path, init, latent_dim, seed, p)) for p in ("fit", "infer"))
    z0 = np.empty((len(exp.dataset()), latent_dim))
    z0[fitted.indices], z0[inferred.indices] = fitted.initial_latents, inferred.initial_latents
    return z0


def psnr(mse: float | None) -> float | None:
    """Peak signal-to-noise ratio in dB of a per-pixel mean squared error of frames in
    [0, 1]: ``10 log10(1 / MSE)`` (None for None)."""
    return None if mse is None else float(10.0 * np.log10(1.0 / max(mse, 1e-12)))


def all_frame_losses(fitted, inferred, data: MotionDataset) -> dict | None:
    """The final losses of an intra run recomputed on *every* frame, for runs that
    trained the vision loss (None otherwise).

    A run with ``vision_frames = K`` logs a K-frame estimate of the vision loss at each
    epoch; this is the exact loss of its final codes (:func:`primspace.train.evaluate`,
    all T frames), with vision also as PSNR (:func:`psnr`).

    Returns
    -------
    dict or None
        ``{"fit": {...}, "infer": {...}}``, each with ``loss``, ``motor``, ``vision``
        (per-pixel MSE of frames in [0, 1]) and ``psnr`` (dB).
    """
    from primspace.train import evaluate

    out = {}
    for phase, run in (("fit", fitted), ("infer", inferred)):
        losses = evaluate(run, data, indices=run.indices, batch_size=256)
        if losses["vision"] is None:
            return None
        out[phase] = losses | {"psnr": psnr(losses["vision"])}
    return out


def point_jobs(
    run_dir: Path,
    data: MotionDataset,
    preset: ExperimentPreset,
    init: str,
    latent_dim: int,
    seed: int,
    train_idx,
    eval_idx,
    use_images: bool,
) -> tuple[dict, dict]:
    """The keyword arguments of :func:`primspace.train.fit` and :func:`primspace.train.infer`
    (``progress`` aside) of one grid point's two phases, each resuming its run directory:
    fit θ and the codes on ``train_idx`` into the fit of :func:`fit_point_dir` (a calibrated
    point's is its projection point's), then infer the codes of ``eval_idx`` with θ frozen
    into ``run_dir/infer``. The one place these runs are defined (:func:`fit_and_infer`,
    :func:`pack_grid_runs`).

    Returns
    -------
    (dict, dict)
        The fit's and the inference's arguments.
    """
    model_config, train_config = train_configs(preset, latent_dim, seed, preset.fit_epochs)
    fit_dir = fit_point_dir(run_dir, init) / "fit"
    fit_job = dict(
        dataset=data,
        out_dir=fit_dir,
        resume=True,
        model_config=model_config,
        train_config=train_config,
        init=fit_init(init),
        indices=np.asarray(train_idx),
        images=use_images,
        scaler=experiment_scaler(data),
    )
    infer_job = dict(
        run=fit_dir,
        dataset=data,
        out_dir=run_dir / "infer",
        resume=True,
        epochs=preset.infer_epochs,
        init=init,
        indices=np.asarray(eval_idx),
        batch_size=preset.infer_batch_size,
    )
    return fit_job, infer_job


def fit_and_infer(
    run_dir: Path,
    data: MotionDataset,
    preset: ExperimentPreset,
    init: str,
    latent_dim: int,
    seed: int,
    train_idx,
    eval_idx,
    use_images: bool,
):
    """One grid point's two phases (:func:`point_jobs`): fit θ and the codes on
    ``train_idx``, then infer the codes of ``eval_idx`` with θ frozen, into ``run_dir/fit``
    and ``run_dir/infer`` (each resumes from its checkpoint when the point was
    interrupted). A calibrated point infers with its projection point's fit, resumed
    under :func:`fit_lock`.

    Returns
    -------
    (TrainedRun, TrainedRun, float)
        The fitted and the inferred runs, and the fit's wall-clock seconds.
    """
    import time

    from primspace.train import configure_process, fit, infer

    start = time.perf_counter()
    fit_job, infer_job = point_jobs(run_dir, data, preset, init, latent_dim, seed, train_idx, eval_idx, use_images)
    configure_process(fit_job["train_config"])  # one thread per run (the preset's threads), as every backend
    with fit_lock(fit_job["out_dir"]):
        fitted = fit(**fit_job, progress=False)
    fit_seconds = time.perf_counter() - start
    inferred = infer(**infer_job, progress=False)
    return fitted, inferred, fit_seconds


# ------------------------------------------------------------------ runs packed


def pack_grid_runs(
    points: list[tuple],
    data: MotionDataset,
    preset: ExperimentPreset,
    use_images: bool,
    pack: int,
    progress: bool | None = None,
) -> dict[str, list[Path]]:
    """Train the unfinished runs of grid points packed, up to ``pack`` at once on one device
    (:mod:`primspace.train.packed`): first their fits (a fit that points share, once), then
    the inferences whose fit is finished. Each run is :func:`point_jobs`'s, in its own run
    directory, so the grid run afterwards (:func:`fit_and_infer`) resumes it and finds it
    finished; a packed run is the run alone within float tolerance, not bit for bit.

    Runs pack when :func:`~primspace.train.packed.pack_key` agrees (one latent size, one
    number of samples). A point whose ``result.json`` exists, and a run that is finished or
    whose checkpoint cannot be read, is left alone; a run that cannot start or a pack that
    fails (e.g. a run diverged) is logged and left to the grid, which trains it alone and
    records its failure as usual.

    Parameters
    ----------
    points : list of tuple
        ``(run_dir, init, latent_dim, seed, train_idx, eval_idx)`` of each grid point, as
        :func:`fit_and_infer` takes them.
    data, preset, use_images
        As :func:`fit_and_infer` (:func:`load_run_data`).
    pack : int
        The most runs trained at once.

    Returns
    -------
    dict
        ``trained``: the run directories trained to their end here; ``left``: those left to the grid.
    """
    from primspace.train import configure_process
    from primspace.train.sessions import fit_session, infer_session

    jobs = [
        (q, *point_jobs(run_dir, data, preset, init, q, seed, train_idx, eval_idx, use_images))
        for run_dir, init, q, seed, train_idx, eval_idx in points
        if not (run_dir / RESULT_FILE).exists()
    ]
    done: dict[str, list[Path]] = {"trained": [], "left": []}
    if not jobs:
        return done
    configure_process(jobs[0][1]["train_config"])  # as fit_and_infer: the preset's threads
    fits = {str(fit_job["out_dir"]): (q, fit_job) for q, fit_job, _ in jobs}  # a shared fit once
    pending = [(q, job) for q, job in fits.values() if _unfinished(job["out_dir"], preset.fit_epochs)]
    _train_in_packs(fit_session, pending, pack, progress, "fit", done)
    pending = [
        (q, infer_job)
        for q, fit_job, infer_job in jobs
        if _trained_epochs(fit_job["out_dir"]) == preset.fit_epochs
        and _unfinished(infer_job["out_dir"], preset.infer_epochs)
    ]
    _train_in_packs(infer_session, pending, pack, progress, "infer", done)
    return done


def _trained_epochs(run_dir: Path) -> int | None:
    """The epochs of the checkpoint in ``run_dir`` (0: none yet), None when it cannot be read."""
    from primspace.train.checkpoint import read_checkpoint
    from primspace.train.rundir import CHECKPOINT_NAME

    try:
        ckpt = read_checkpoint(Path(run_dir) / CHECKPOINT_NAME, "cpu")
        return 0 if ckpt is None else int(ckpt["epoch"])
    except (UserError, KeyError, TypeError, ValueError):
        return None


def _unfinished(run_dir: Path, epochs: int) -> bool:
    """Whether the run in ``run_dir`` is to be trained (on to ``epochs``) packed."""
    trained = _trained_epochs(run_dir)
    return trained is not None and trained < epochs


def _train_in_packs(build, jobs: list[tuple], pack: int, progress, label: str, done: dict) -> None:
    """Build the session of each ``(latent_dim, job)`` (``build``: fit_session or
    infer_session) and train them in packs of up to ``pack`` whose pack keys agree, one
    latent size after the other (so that few sessions wait in memory); ``done`` gets their
    run directories."""
    from primspace.train.packed import pack_key

    buckets: dict[tuple, list] = {}
    try:
        for q, job in sorted(jobs, key=lambda j: j[0]):
            if any(key[0] != q for key in buckets):  # the next latent size: the last one's packs train now
                for key in list(buckets):
                    _train_pack(buckets.pop(key), progress, label, done)
            try:
                prepared = build(**job)
            except UserError as exc:
                log.warning("%s: not trained packed, left to the grid (%s)", job["out_dir"], exc)
                done["left"].append(Path(job["out_dir"]))
                continue
            key = (q, pack_key(prepared[0]))
            buckets.setdefault(key, []).append(prepared)
            if len(buckets[key]) >= pack:
                _train_pack(buckets.pop(key), progress, label, done)
        for key in list(buckets):
            _train_pack(buckets.pop(key), progress, label, done)
    finally:
        for bucket in buckets.values():  # an unexpected error: no run keeps its writer's lock
            for session, _ in bucket:
                session.close()


def _train_pack(prepared: list[tuple], progress, label: str, done: dict) -> None:
    """Train the sessions ``prepared`` (with their checkpoints) packed, one alone; a failure
    is logged and its runs left to the grid."""
    import torch

    from primspace.train import TrainingDivergedError
    from primspace.train.packed import train_packed
    from primspace.train.sessions import run_session

    sessions = [session for session, _ in prepared]
    try:
        if len(prepared) == 1:
            run_session(*prepared[0], progress, label)  # alone, as the grid would train it
        else:
            train_packed(prepared, progress, label)
    except (UserError, TrainingDivergedError, torch.cuda.OutOfMemoryError) as exc:
        names = ", ".join(str(s.run_dir.path) for s in sessions)
        log.warning("%s %d runs packed failed, left to the grid (%s): %s", label, len(sessions), exc, names)
    finally:
        for session in sessions:
            session.close()  # train_packed closes them, except when it refuses them
    for session in sessions:
        finished = session.epoch >= session.tc.epochs
        done["trained" if finished else "left"].append(session.run_dir.path)
