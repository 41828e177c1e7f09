"""Intra-primitive generalisation (paper, *Experimental Results*, Figs. "Convergence of the loss").

A random 20% of the samples (drawn per primitive, so every primitive is in both parts)
fit the decoder's weights θ and their codes Z; the other 80% get codes by inference with
θ frozen. Each latent initialisation (zero, random, projection, PCA) and latent size q is
one run of the grid ``intra/<init>-q<q>-s<seed>``. The figures are the paper's two
convergence plots: the loss over the fitting epochs and over the inference epochs.

This module also draws what is read off the same runs: the latent-space figure (first
principal components of one primitive's codes coloured by block position, the paper's
"latent encoding" figure) and generated-vs-recorded motions (Appendix B).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.presets import ExperimentPreset
from primspace.experiments.sweep import GridPoint, run_dir_of
from primspace.experiments.workspace import ExperimentDir, read_meta, read_results

__all__ = [
    "split_indices",
    "run_intra",
    "run_intra_point",
    "intra_key",
    "load_codes",
    "report_summary",
    "report_data",
    "report_section",
    "report_latent_figures",
    "report_appendix_a",
]


def split_indices(labels: np.ndarray, train_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random split with ``train_fraction`` of every label's samples in the first part.

    Each label keeps at least one sample on each side (when it has two or more).
    Returns sorted ``(train, eval)`` index arrays.
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 20]))
    train = []
    for label in np.unique(labels):
        members = np.flatnonzero(labels == label)
        rng.shuffle(members)
        k = int(round(train_fraction * len(members)))
        k = min(max(k, 1), max(len(members) - 1, 1))
        train.extend(members[:k].tolist())
    train = np.sort(np.array(train, dtype=np.int64))
    evaluation = np.setdiff1d(np.arange(len(labels)), train)
    return train, evaluation


def intra_key(init: str, latent_dim: int, seed: int) -> str:
    return f"intra/{init}-q{latent_dim}-s{seed}"


def _configs(preset: ExperimentPreset, latent_dim: int, seed: int, epochs: int):
    from primspace.model import ModelConfig
    from primspace.train import TrainConfig

    model_config = ModelConfig(latent_dim=latent_dim, layer_sizes=preset.layer_sizes, taus=preset.taus)
    train_config = TrainConfig(
        epochs=epochs, batch_size=preset.batch_size, lr=preset.lr, latent_lr=preset.latent_lr,
        final_lr_fraction=preset.final_lr_fraction,
        vision_weight=preset.vision_weight, seed=seed, checkpoint_every=max(1, epochs // 10),
        threads=1,  # runs are parallel across processes; one thread each keeps every backend bit-identical
    )
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


def _curves(history: list[dict]) -> list[dict]:
    """The per-epoch losses of a run (its metrics.jsonl without timings)."""
    return [{k: h.get(k) for k in ("epoch", "loss", "motor", "vision")} for h in history]


def run_intra_point(
    run_dir: Path, data_path: str, train_idx: list, eval_idx: list, init: str, latent_dim: int, seed: int, preset: dict
) -> dict:
    """One grid point: fit θ and Z on the train part, then infer Z on the eval part.

    Both phases resume from their checkpoints if the point was interrupted.
    """
    from primspace.train import fit, infer

    preset_obj = ExperimentPreset.from_dict(preset)
    data, use_images = load_run_data(data_path, preset_obj)
    start = time.perf_counter()
    model_config, train_config = _configs(preset_obj, latent_dim, seed, preset_obj.fit_epochs)
    fitted = fit(
        data, run_dir / "fit", model_config=model_config, train_config=train_config, init=init,
        indices=np.asarray(train_idx), resume=True, images=use_images, scaler=experiment_scaler(data), progress=False,
    )
    fit_seconds = time.perf_counter() - start
    inferred = infer(
        run_dir / "fit", data, run_dir / "infer", epochs=preset_obj.infer_epochs, init=init,
        indices=np.asarray(eval_idx), resume=True, progress=False, batch_size=preset_obj.infer_batch_size,
    )
    return {
        "init": init,
        "latent_dim": latent_dim,
        "seed": seed,
        "n_train": len(train_idx),
        "n_eval": len(eval_idx),
        "fit": _curves(fitted.history),
        "infer": _curves(inferred.history),
        "fit_seconds": round(fit_seconds, 2),
        "seconds": round(time.perf_counter() - start, 2),
    }


def run_intra(exp: ExperimentDir) -> dict:
    """Run (or finish) the intra-primitive grid; write results/intra.json and its figures."""
    preset = exp.preset
    data = exp.dataset()
    points, splits = [], {}
    for seed in preset.seeds:
        train, evaluation = split_indices(data.labels, preset.train_fraction, seed)
        splits[str(seed)] = {"train": train.tolist(), "eval": evaluation.tolist()}
        for q in preset.latent_dims:
            for init in preset.inits:
                args = (str(exp.data_path), train.tolist(), evaluation.tolist(), init, q, seed, preset.to_dict())
                points.append(GridPoint(intra_key(init, q, seed), args))
    with exp.stage("intra"):
        grid = exp.grid(run_intra_point, points, "intra-primitive runs")
    runs = [grid.results[p.key] | {"key": p.key} for p in points if p.key in grid.results]
    results = {
        "runs": runs,
        "failures": grid.failures,
        "splits": {s: {"n_train": len(v["train"]), "n_eval": len(v["eval"])} for s, v in splits.items()},
        "label_names": list(data.label_names),
    }
    exp.write_results("intra", results)
    _intra_figures(exp, results)
    return results


def load_codes(exp: ExperimentDir, init: str, latent_dim: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """All samples' codes of one intra run, in data-set order, and a mask of the train part.

    Returns ``(Z, is_train)``: ``Z`` (N, q) with the fitted codes of the train samples
    and the inferred codes of the eval samples.
    """
    from primspace.train import load_run

    run_dir = run_dir_of(exp.path, intra_key(init, latent_dim, seed))
    fitted, inferred = load_run(run_dir / "fit"), load_run(run_dir / "infer")
    n = len(exp.dataset())
    z = np.full((n, latent_dim), np.nan, dtype=np.float32)
    z[fitted.indices] = fitted.latents
    z[inferred.indices] = inferred.latents
    is_train = np.zeros(n, dtype=bool)
    is_train[fitted.indices] = True
    return z, is_train


# ------------------------------------------------------------------------- figures


def _intra_figures(exp: ExperimentDir, results: dict) -> None:
    from primspace import plots

    if not results["runs"]:
        return
    for phase, title in (("fit", "fit θ and Z (train part)"), ("infer", "infer Z, θ frozen (eval part)")):
        fig = plots.plot_intra_losses(results["runs"], phase=phase, title=f"Intra-primitive: {title}")
        plots.save_figure(fig, exp.figure(f"intra_loss_{phase}"))
    _latent_figures(exp, results)


def _focus_runs(exp: ExperimentDir, results: dict) -> tuple[int, int, list[str]]:
    """(q, seed, inits) of the runs the latent figures are drawn from."""
    preset = exp.preset
    q = preset.cluster_latent_dim if preset.cluster_latent_dim in preset.latent_dims else max(preset.latent_dims)
    seed = preset.seeds[0]
    done = {(r["init"], r["latent_dim"], r["seed"]) for r in results["runs"]}
    return q, seed, [i for i in preset.inits if (i, q, seed) in done]


def _latent_figures(exp: ExperimentDir, results: dict) -> None:
    from primspace import plots
    from primspace.train import load_run

    data = exp.dataset()
    q, seed, inits = _focus_runs(exp, results)
    if not inits:
        return
    codes = {init: load_codes(exp, init, q, seed)[0] for init in inits}
    primitive = 0
    if data.params is not None:
        for dims in (2, 3):
            fig = plots.plot_latent_pca(
                codes, data.labels, data.params, primitive=primitive,
                primitive_name=data.label_names[primitive], n_components=dims,
            )
            plots.save_figure(fig, exp.figure(f"latent_pca{dims}d"))
    # Appendix B: generated vs recorded, one eval sample of each primitive the paper shows
    init = "projection" if "projection" in inits else inits[0]
    run = load_run(run_dir_of(exp.path, intra_key(init, q, seed)) / "infer")
    wanted = [n for n in ("grasp", "push", "circle_cw") if n in data.label_names] or list(data.label_names[:3])
    for name in wanted:
        members = run.indices[data.labels[run.indices] == data.label_names.index(name)]
        if members.size:
            fig = plots.plot_reconstruction(run, data, int(members[0]))
            plots.save_figure(fig, exp.figure(f"reconstruction_{name}"))


# -------------------------------------------------------------------------- report


def _final(curve: list) -> float:
    vals = [v for v in curve if v is not None]
    return float(vals[-1]) if vals else float("nan")


def final_loss_table(results: dict) -> tuple[list[str], list[list]]:
    """Rows ``init, q, seed, fit loss, eval loss at epoch 0, eval loss at the end``."""
    rows = []
    for r in sorted(results["runs"], key=lambda r: (r["latent_dim"], r["seed"], r["init"])):
        fit_loss = [h["loss"] for h in r["fit"]]
        eval_loss = [h["loss"] for h in r["infer"]]
        rows.append([r["init"], r["latent_dim"], r["seed"], _final(fit_loss), eval_loss[0], _final(eval_loss)])
    return ["init", "q", "seed", "final fit loss", "eval loss before inference", "final eval loss"], rows


def qualitative_check(results: dict) -> tuple[bool | None, str]:
    """Does projection's final eval loss lie below zero's and random's at every q? (the paper's claim)"""
    by = {}
    for r in results["runs"]:
        by.setdefault((r["latent_dim"], r["seed"]), {})[r["init"]] = _final([h["loss"] for h in r["infer"]])
    verdicts, lines = [], []
    for (q, seed), losses in sorted(by.items()):
        if not {"projection", "zero", "random"} <= losses.keys():
            continue
        ok = losses["projection"] < losses["zero"] and losses["projection"] < losses["random"]
        verdicts.append(ok)
        lines.append(
            f"q={q}, seed {seed}: projection {losses['projection']:.4g}, zero {losses['zero']:.4g}, "
            f"random {losses['random']:.4g} — {'holds' if ok else 'does NOT hold'}"
        )
    if not verdicts:
        return None, "not enough runs to compare projection with zero and random"
    return all(verdicts), "; ".join(lines)


def report_summary(out_dir: Path, report) -> None:
    results = read_results(out_dir, "intra")
    report.section("Summary")
    if results is None:
        report.paragraph("No intra-primitive results yet.")
        return
    ok, text = qualitative_check(results)
    if ok is None:
        report.note(text, "warn")
    elif ok:
        report.note(
            "The paper's central result, as we test it, holds here: after inference with θ frozen, codes "
            "initialised by random projection reach a lower evaluation loss than zero and random "
            "initialisation. (The paper's own sentences are checked one by one in the next section.) " + text, "good",
        )
    else:
        report.note(
            "The paper's central result, as we test it, does NOT hold in every case here (projection's final "
            "evaluation loss is not below both zero and random initialisation). " + text, "warn",
        )
    if results["failures"]:
        report.note(f"{len(results['failures'])} run(s) failed: " + "; ".join(f"{k}: {v}" for k, v in results["failures"].items()), "warn")


def report_data(out_dir: Path, report) -> None:
    meta = read_meta(out_dir)
    path = Path(meta["data"])
    if not path.exists():
        return
    s = MotionDataset.load(path).summary()
    report.section("Data")
    report.paragraph(
        f"{s['n_samples']} samples, T = {s['length']} steps, J = {s['n_joints']} joints "
        f"({', '.join(s['joint_names'])}), images {('x'.join(map(str, s['image_shape'])) if s['image_shape'] else 'none')}; "
        f"file {path}."
    )
    report.code(s["source"])
    if s["label_counts"]:
        report.table(["primitive", "samples"], list(s["label_counts"].items()))


def report_section(out_dir: Path, report) -> None:
    results = read_results(out_dir, "intra")
    if results is None:
        return
    report.section("Intra-primitive generalisation")
    split = next(iter(results["splits"].values()), {})
    report.paragraph(
        f"θ and Z fitted on {split.get('n_train', '?')} samples (the train part), Z inferred with θ frozen on "
        f"{split.get('n_eval', '?')} samples (the eval part), per initialisation and latent size q. "
        "Loss: mean squared error of the motor sequence scaled to [-1, 1], plus the vision weight times "
        "the mean squared error of the frames in [0, 1]. Epoch 0 is the loss of the initial codes."
    )
    preset = read_meta(out_dir)["preset_config"]
    if not preset["images"]:
        report.note(
            f"The '{preset['name']}' preset trains on joint angles only (no vision loss), to fit its CPU time "
            "budget; the camera images are generated and shown, but not learned. The paper preset learns both.",
            "warn",
        )
    report.figure(out_dir / "figures/intra_loss_fit.png", "Loss while fitting θ and Z (the paper's first convergence figure).")
    report.figure(out_dir / "figures/intra_loss_infer.png", "Loss while inferring Z with θ frozen (the paper's second convergence figure).")
    columns, rows = final_loss_table(results)
    report.table(columns, rows, "Final losses per run.")


def report_latent_figures(out_dir: Path, report) -> None:
    figs = sorted((out_dir / "figures").glob("latent_pca*.png")) + sorted((out_dir / "figures").glob("reconstruction_*.png"))
    if not figs:
        return
    report.section("Latent space and reconstructions")
    for fig in figs:
        if fig.name.startswith("latent_pca"):
            caption = (
                "First principal components of one primitive's codes (train and eval), coloured by the block "
                "position on the table (left: the positions), per initialisation — the paper's latent-encoding figure."
            )
        else:
            caption = "Generated (dashed, lower frames) against recorded (solid, upper frames) — the paper's Appendix B."
        report.figure(fig, caption)


def report_appendix_a(out_dir: Path, report) -> None:
    from primspace.data import JointScaler
    from primspace.latent import appendix_a_check

    meta = read_meta(out_dir)
    if not Path(meta["data"]).exists():
        return
    data = MotionDataset.load(meta["data"])
    flat = JointScaler().fit_transform(data.motor).reshape(len(data), -1)
    # two motions of the same primitive and two of different primitives, as the paper's a and b
    first = np.flatnonzero(data.labels == data.labels[0])
    other = np.flatnonzero(data.labels != data.labels[0])
    pairs = [("same primitive", first[0], first[-1])]
    if other.size:
        pairs.append(("different primitives", first[0], other[0]))
    report.section("Appendix A: random projections keep inner products")
    report.paragraph(
        "For P with entries N(0, 1/q), the paper shows E[Pa·Pb] = a·b and "
        "Var[Pa·Pb] ≤ (3|a|²|b|² − (a·b)²)/q. Checked by drawing 2000 matrices P, with a and b two "
        "scaled, flattened motor sequences of this data set. 'mean z' is the deviation of the sample "
        "mean from a·b in standard errors; the exact variance for Gaussian P is (|a|²|b|² + (a·b)²)/q."
    )
    rows = []
    for name, i, j in pairs:
        for q in sorted({10, 20, 40} | {int(meta["preset_config"]["cluster_latent_dim"])}):
            c = appendix_a_check(flat[i], flat[j], q, n_draws=2000, random_state=q)
            rows.append([name, q, c["dot"], c["mean"], c["mean_z"], c["var"], c["var_exact"], c["var_bound"],
                         "yes" if c["var"] <= c["var_bound"] else "no"])
    report.table(["pair", "q", "a·b", "mean Pa·Pb", "mean z", "var", "exact var", "bound", "var ≤ bound"], rows)
