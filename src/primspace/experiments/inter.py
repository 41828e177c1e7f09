"""Inter-primitive generalisation (paper, Fig. "Mean and standard deviation ... inter-primitive").

Seven folds, one per primitive: phase 1 fits θ and Z on the other six primitives; phase 2
continues θ (and the replayed codes) on the seventh primitive plus a 10% replay of
phase-1 samples (to avoid forgetting), new codes initialised by the method compared. The
figure is the phase-2 loss, mean ± std over folds, for zero and projection initialisation
(q = 20). Both phases resume from their checkpoints.

``calibrated`` (beyond the paper): phase 1 is projection's (shared, :func:`shared_fit`);
the new primitive's codes start at phase 1's calibration map applied to their ``P m``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from primspace.experiments import figures
from primspace.experiments.appendix_a import run_appendix_a
from primspace.experiments.presets import ExperimentPreset
from primspace.experiments.runs import (
    curves,
    experiment_scaler,
    load_run_data,
    shared_fit,
    shared_fits_last,
    train_configs,
)
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import fit_init, fit_point_dir

__all__ = ["run_inter", "run_inter_point", "replay_indices", "inter_key"]


def replay_indices(first: np.ndarray, fraction: float, seed: int, fold: int) -> np.ndarray:
    """A seeded ``fraction`` of phase-1 samples (at least one), sorted."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(fold), 30]))
    k = max(1, int(round(fraction * len(first))))
    return np.sort(rng.choice(first, size=k, replace=False))


def run_inter_point(
    run_dir: Path, data_path: str, fold: int, init: str, latent_dim: int, seed: int, preset: dict
) -> dict:
    """One fold: phase 1 on six primitives, phase 2 on the held-out one plus replay."""
    from primspace.train import configure_process, fit

    p = ExperimentPreset.from_dict(preset)
    data, use_images = load_run_data(data_path, p)
    start = time.perf_counter()
    first = np.flatnonzero(data.labels != fold)
    new = np.flatnonzero(data.labels == fold)
    model_config, tc1 = train_configs(p, latent_dim, seed, p.inter_epochs[0])
    configure_process(tc1)  # one thread per run (the preset's threads), as every backend
    phase1_dir = fit_point_dir(run_dir, init) / "phase1"
    phase1 = shared_fit(
        phase1_dir,
        dataset=data,
        model_config=model_config,
        train_config=tc1,
        init=fit_init(init),
        indices=first,
        images=use_images,
        scaler=experiment_scaler(data),
        progress=False,
    )
    replay = replay_indices(first, p.inter_replay, seed, fold)
    second = np.concatenate([new, replay])
    initial = np.full((len(second), latent_dim), np.nan, dtype=np.float32)
    row_of = {int(s): r for r, s in enumerate(phase1.indices)}
    initial[len(new) :] = phase1.latents[[row_of[int(s)] for s in replay]]
    _, tc2 = train_configs(p, latent_dim, seed, p.inter_epochs[1])
    phase2 = fit(
        data,
        run_dir / "phase2",
        train_config=tc2,
        init=init,
        indices=second,
        resume=True,
        weights_from=phase1_dir,
        initial_latents=initial,
        images=use_images,
        progress=False,
    )
    return {
        "fold": fold,
        "primitive": data.label_names[fold],
        "init": init,
        "latent_dim": latent_dim,
        "seed": seed,
        "n_phase1": len(first),
        "n_new": len(new),
        "n_replay": len(replay),
        "phase1": curves(phase1.history),
        "phase2": curves(phase2.history),
        "seconds": round(time.perf_counter() - start, 2),
    }


def inter_key(init: str, fold: int, seed: int) -> str:
    """The grid key (and ``OUT/runs/`` folder) of one inter-primitive fold."""
    return f"inter/{init}-fold{fold}-s{seed}"


def run_inter(exp: ExperimentDir) -> dict:
    """Run (or finish) the seven folds per init; write results/inter.json and its figure."""
    preset = exp.preset
    data = exp.dataset()
    folds = sorted(int(v) for v in np.unique(data.labels))
    points = [
        GridPoint(
            inter_key(init, fold, seed),
            (str(exp.data_path), fold, init, preset.inter_latent_dim, seed, preset.to_dict()),
        )
        for seed in preset.seeds
        for init in preset.inter_inits
        for fold in folds
    ]
    with exp.stage("inter"):
        grid = exp.grid(run_inter_point, shared_fits_last(points), "inter-primitive folds")
    results = {
        "runs": [grid.results[p.key] | {"key": p.key} for p in points if p.key in grid.results],
        "failures": grid.failures,
        "latent_dim": preset.inter_latent_dim,
        "replay": preset.inter_replay,
    }
    exp.write_results("inter", results)
    run_appendix_a(exp)
    figures.draw_inter(exp.path)
    return results
