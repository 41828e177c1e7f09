"""Prediction command: predict (the rest of each motion from its observed beginning, with ``--primitive``
as that primitive, or with ``--scene`` a whole motion from the first frame and the primitive named;
docs/predict.md).

``--scene`` runs the scene policy (:func:`primspace.act.scene_policy.predict_from_scene`: the
block's colour in the first frame to the motion, per primitive; docs/act.md)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.observing import observed_amount, observed_text
from primspace.cli.options import allow_unfinished_option, check_finished, threads_option
from primspace.utils.errors import UserError

#: The mark ``predict`` writes into its data file and figure (primspace.utils.outputs).
PREDICT_MARK = "primspace predict"
#: The files of a ``primspace predict`` output directory (result.json last: it says the output is complete).
PREDICT_FILES = ("predicted.h5", "prediction.png", "posterior.png", "result.json")
_SHOWN = 4


def _shown_titles(dataset, indices) -> list[str]:
    names = dataset.label_names
    titles = []
    for i in indices:
        label = None if dataset.labels is None else int(dataset.labels[i])
        name = names[label] if names is not None and label is not None and 0 <= label < len(names) else None
        where = "" if dataset.source_ids is None else f" {dataset.source_ids[int(i)]}"
        titles.append(f"sample {int(i)}{where}" + (f" ({name})" if name else ""))
    return titles


def _judged(predicted_dataset) -> dict | None:
    """Success of the predicted motions in the simulator, when the data can be judged (else None)."""
    from primspace.sim.success import check_judgeable, evaluate_dataset, success_rates
    from primspace.utils.errors import DataError

    try:
        check_judgeable(predicted_dataset)
    except DataError:
        return None
    results = evaluate_dataset(predicted_dataset)
    return {"rates": success_rates(results), "per_sample": [bool(r.success) for r in results]}


def _write_outputs(tmp: Path, prediction, predicted, dataset, judged: dict | None, command: dict) -> dict:
    """predicted.h5 (``predicted``: the prediction as a data set), prediction.png and
    result.json into ``tmp``; the result's dict."""
    from primspace.plots import plot_predictions, save_figure

    data = dataset.subset(prediction.indices)
    predicted.save(tmp / "predicted.h5", writer=PREDICT_MARK)
    shown = list(range(min(_SHOWN, len(data))))
    fig = plot_predictions(
        data.motor[shown],
        prediction.motor[shown],
        prediction.motor_observed[shown],
        titles=_shown_titles(dataset, prediction.indices[shown]),
        joint_names=data.joint_names,
        dt=data.dt,
    )
    save_figure(fig, tmp / "prediction.png", writer=PREDICT_MARK)
    per_sample = {
        name: [None if not float(v) == float(v) else float(v) for v in values]
        for name, values in prediction.errors.items()
    }
    from primspace.predict.registry import model_share

    result = {
        **prediction.summary(),
        "model_share": model_share(prediction.details, True),  # the command's predictors are built on the run
        "command": command,
        "indices": [int(i) for i in prediction.indices],
        "source_ids": None if data.source_ids is None else [str(v) for v in data.source_ids],
        "per_sample": per_sample,
        "success": judged,
        "writer": PREDICT_MARK,
    }
    (tmp / "result.json").write_text(json.dumps(result, indent=2))
    return result


@app.command("predict")
def predict_command(
    run: Path = typer.Argument(..., help="A fitted run directory (its weights are frozen)."),
    file: Path = typer.Argument(..., metavar="DATA", help="A MotionDataset HDF5 file with the motions to predict."),
    out: Path = typer.Option(
        ...,
        "--out",
        "-o",
        help="The folder to write (predicted.h5, result.json, prediction.png; posterior.png with the prior "
        "and no --primitive).",
    ),
    observe: str | None = typer.Option(
        None,
        "--observe",
        help="Observed joints: a fraction of each motion's valid steps, 0.25 (the default) or 25%, or none "
        "(frames only). A whole number is refused: steps go in --observe-steps.",
    ),
    observe_steps: int | None = typer.Option(
        None, "--observe-steps", help="Observed joints: the first N steps of each motion (instead of --observe)."
    ),
    observe_frames: str | None = typer.Option(
        None,
        "--observe-frames",
        help="Observed frames: a fraction (0.25 or 25%), first (the first frame) or none. Default: as --observe.",
    ),
    observe_frames_steps: int | None = typer.Option(
        None, "--observe-frames-steps", help="Observed frames: the first N steps (instead of --observe-frames)."
    ),
    init: str | None = typer.Option(
        None,
        "--init",
        "--predictor",
        help="The predictor. auto (the default): the one with the lowest K-fold error on the fitted "
        "demonstrations for this task, chosen once and kept in RUN/selection/ (primspace fit-predictor "
        "shows the table): without --primitive the mixture or the prior, with it the prior given it or "
        "the mixture restricted to it. Or name one: mixture (the posterior over the fitted codes, no "
        "gradient; with --primitive restricted to that label), prior (a prior in code space per "
        "primitive: given --primitive, or weighted by the posterior over primitives), or a start of "
        "gradient inference: zero, random, projection, pca, calibrated, nearest.",
    ),
    continuity: bool = typer.Option(
        True,
        "--continuity/--no-continuity",
        help="Remove the jump at the last observed step (default on, as in Python).",
    ),
    epochs: int = typer.Option(
        100, "--epochs", help="Gradient starts: inference epochs on the observed entries (0: the start as it is)."
    ),
    indices: Path | None = typer.Option(None, "--indices", help="Samples of FILE to predict (.npy or text)."),
    fitted: Path | None = typer.Option(
        None,
        "--fitted-data",
        help="The data file the run was fitted on (default: the run's own), read by mixture, prior, nearest, "
        "calibrated and --scene (the scene policy learns from its frames).",
    ),
    latent_lr: float | None = typer.Option(
        None, "--latent-lr", help="Gradient starts: the codes' learning rate (default: the run's)."
    ),
    seed: int | None = typer.Option(
        None, "--seed", help="Seed of a random start, or of the scene policy (default: the run's)."
    ),
    threads: int | None = threads_option(),
    online: bool = typer.Option(
        False,
        "--online",
        help="Steps arrive one at a time: --iterations inference steps "
        "after each, warm-started (predictive coding); result.json gets the latency per step "
        "and the error of the rest after each step.",
    ),
    iterations: int | None = typer.Option(
        None,
        "--iterations",
        help="With --online and gradient inference (--init zero, random, ...): inference iterations per arriving "
        "step (default 5); the mixture and the prior read none.",
    ),
    scene: bool = typer.Option(
        False,
        "--scene",
        help="The scene only: the whole motion from the first frame and the first joints, as the "
        "primitive to perform (--primitive), by the scene policy (the block's colour in the first "
        "frame to the motion, fitted on the run's fitted demonstrations and their frames). Not with --observe, "
        "--observe-frames, --init, --online, --latent-lr; --epochs is not read.",
    ),
    primitive: str | None = typer.Option(
        None,
        "--primitive",
        help="The primitive of every motion, a name (push) or its number in the run's list of primitives "
        "(not a label id): the prior "
        "predictor (--init prior) predicts each motion as it; without it the prior weighs its "
        "primitives by their posterior. With --scene: the primitive to perform, a name (a label "
        "name, or 'cluster 2') or an id of --primitives (result.json lists them).",
    ),
    primitives: str | None = typer.Option(
        None,
        "--primitives",
        "-k",
        help="The prior's primitives: labels (of the fitted data, the default), "
        "clusters (of the fitted codes, as many as the labels) or a number K of clusters. With "
        "--scene the same; default: labels when the fitted data has labels, else clusters (give K).",
    ),
    clusters: int | None = typer.Option(
        None, "--clusters", hidden=True, help="The number of clusters K of --primitives clusters (as --primitives K)."
    ),
    prior_samples: int | None = typer.Option(
        None, "--prior-samples", help="The prior: codes drawn and decoded per primitive (default 2000, at most 50000)."
    ),
    no_judge: bool = typer.Option(False, "--no-judge", help="Do not replay simulator data to judge success."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it is an earlier predict output."),
    allow_unfinished: bool = allow_unfinished_option(),
) -> None:
    """Predict the rest of each motion: codes inferred from the observed beginning, the whole sequence decoded
    (with --scene: the whole motion from the first frame and joints, as the named primitive, by the scene policy)."""
    from primspace.train import TrainConfig, configure_process, load_run
    from primspace.train.checks import check_data_fits
    from primspace.utils.files import check_outside_inputs
    from primspace.utils.folders import OutputKind, atomic_directory
    from primspace.utils.seeds import check_seed

    if seed is not None:
        check_seed(seed, "--seed")
    source, clusters = parse_primitives(primitives, clusters, scene)
    observed = {
        "--observe": (observe, observe_steps),
        "--observe-frames": (observe_frames, observe_frames_steps),
    }
    motor, frames = _amounts(scene, primitive, observed, init, online)
    if scene and latent_lr is not None:
        raise UserError("--latent-lr goes with gradient inference, not with --scene (the scene policy has no codes)")
    prior = _prior_options(scene, init, primitive, source, clusters, prior_samples)
    check_outside_inputs(out, (file, indices, run, fitted))
    _check_ignored(iterations, online, fitted, init, scene)
    kind = OutputKind("primspace predict", PREDICT_FILES, frozenset({"observe", "mean", "writer"}))
    overrides = {k: v for k, v in (("latent_lr", latent_lr), ("seed", seed)) if v is not None}
    configure_process(TrainConfig(threads=threads).validate())
    with atomic_directory(out, overwrite, kind) as tmp:  # checked and locked before any work
        trained = load_run(run)
        check_finished(trained, allow_unfinished)
        dataset, idx, fitted_data = _inputs(file, indices, fitted)
        if not scene:  # the file named in one line, before a predictor is fitted
            check_data_fits(dataset, trained.model_config, use_images=False)
        common = dict(epochs=epochs, indices=idx, fitted_data=fitted_data, threads=threads, **overrides)
        prediction, command = _predict(
            trained,
            dataset,
            scene,
            prior,
            motor,
            frames,
            init,
            continuity,
            (5 if iterations is None else iterations) if online else None,
            common,
        )
        # --epochs as read: None where no epoch ran (the mixture and the prior do not read it)
        command = {"run": str(run), "data": str(file), "epochs": epochs if prediction.epochs else None, **command}
        predicted = prediction.to_dataset(dataset)
        judged = None if no_judge else _judged(predicted)
        result = _write_outputs(tmp, prediction, predicted, dataset, judged, command)
        if prediction.details.get("posterior") is not None:
            _write_posterior(tmp, prediction, dataset)
    reused = (prediction.details.get("selection") or {}).get("reused")
    if reused:
        chosen = prediction.details["selection"]["chosen"]
        typer.echo(f"reused the predictor chosen earlier for this run, data and task: {chosen} ({reused})")
    typer.echo(_summary_line(out, result, prediction, online, judged, dataset.has_images))


def _predict(run, dataset, scene: bool, prior: dict, motor, frames, init, continuity: bool, online, common):
    """The prediction (scene mode or from the observed beginning) and what result.json records of the command;
    ``prior``: the prior's options (:func:`_prior_options`), empty for another predictor."""
    from primspace.predict import DEFAULT_PREDICTOR, predict

    if scene:
        from primspace.act.scene_policy import SCENE_POLICY, predict_from_scene

        prediction = predict_from_scene(
            run,
            dataset,
            prior["primitive"],
            primitives=prior["primitives"],
            n_clusters=prior["n_clusters"],
            indices=common["indices"],
            fitted_data=common["fitted_data"],
            random_state=common.get("seed"),
        )
        source = prediction.details["policy"]["source"]
        return prediction, {"scene": True, "mode": SCENE_POLICY, **prior, "primitives": source, "epochs": None}
    init = init or DEFAULT_PREDICTOR
    prediction = predict(
        run,
        dataset,
        observe=motor,
        observe_frames=frames,
        init=init,
        continuity=continuity,
        online=online,
        progress=None,
        **prior,
        **common,
    )
    return prediction, {
        "observe": motor,
        "observe_frames": frames,
        "init": init,
        "continuity": continuity,
        "online": online,
        **prior,
    }


def _inputs(file: Path, indices: Path | None, fitted: Path | None) -> tuple:
    """The data set, the indices of the samples to predict (None: all) and the fitted data (None: the run's)."""
    from primspace.data.dataset import MotionDataset
    from primspace.data.indices import read_indices

    dataset = MotionDataset.load(file)
    idx = read_indices(indices, dataset) if indices is not None else None
    return dataset, idx, MotionDataset.load(fitted) if fitted is not None else None


def _amounts(scene: bool, primitive, observed: dict, init, online: bool) -> tuple:
    """``--observe`` (or ``--observe-steps``) and ``--observe-frames`` (or ``--observe-frames-steps``)
    parsed (motor None under ``--scene``), after the ``--scene`` checks; ``observed``: each option's
    (text, steps) as given."""
    from primspace.train.observe import FIRST, NOTHING

    _check_scene_flags(scene, primitive, observed, init, online)
    motor = observed_amount(*observed["--observe"], "--observe", (NOTHING,))
    frames = observed_amount(*observed["--observe-frames"], "--observe-frames", (FIRST, NOTHING))
    return (None if scene else 0.25 if motor is None else motor), frames


def parse_primitives(
    primitives: str | None, clusters: int | None, scene: bool = False
) -> tuple[str | None, int | None]:
    """``--primitives labels|clusters|K`` and ``--clusters K`` as (where the primitives come from, the
    number of clusters or None); one line for a value that is none of these or contradicts the other.
    With ``scene`` and neither given the source is None: labels when the fitted data has labels, else
    clusters (:func:`~primspace.act.scene_policy.predict_from_scene` decides)."""
    k = clusters
    if primitives is None:
        source = "clusters" if clusters is not None else "labels"
    elif primitives.strip().isdigit():
        source, k = "clusters", int(primitives)
        if clusters is not None and clusters != k:
            raise UserError(f"--primitives {primitives} and --clusters {clusters}: give the number of clusters once")
    elif primitives.strip() in ("labels", "clusters"):
        source = primitives.strip()
        if source == "labels" and clusters is not None:
            raise UserError("--clusters counts clusters of the fitted codes: give --primitives clusters, not labels")
    else:
        raise UserError(f"--primitives {primitives!r}: give labels, clusters or a number of clusters K")
    if k is not None and k < 1:
        raise UserError(f"--primitives {k}: the number of clusters must be at least 1")
    if scene and primitives is None and clusters is None:
        return None, None
    return source, k


def _prior_options(scene: bool, init, primitive, source: str, clusters, prior_samples) -> dict:
    """The keywords of :func:`primspace.predict.predict` for the primitive: all of them for auto (no
    ``--init``) and the prior, ``--primitive`` alone for the mixture (restricted to that label); one line
    when ``--init`` names a predictor that does not read one given (empty: none given to read)."""
    from primspace.predict import AUTO, MIXTURE, PRIOR
    from primspace.predict.prior import MAX_PRIOR_SAMPLES

    if scene:
        if prior_samples is not None:
            raise UserError("--prior-samples goes with the prior predictor (--init prior), not with --scene")
        return {"primitive": primitive, "primitives": source, "n_clusters": clusters}
    given = (("--primitive", primitive), ("--primitives", None if source == "labels" else source))
    given += (("--prior-samples", prior_samples),)
    asked = [name for name, value in given if value is not None]
    if init == MIXTURE and asked in ([], ["--primitive"]):
        return {} if primitive is None else {"primitive": primitive}
    if init not in (None, AUTO, PRIOR):
        if asked:
            raise UserError(
                f"--init {init} takes no {', '.join(asked)}: the prior (--init prior) and auto (no --init) take "
                "them, the mixture takes --primitive alone"
            )
        return {}
    if prior_samples is not None and not 2 <= prior_samples <= MAX_PRIOR_SAMPLES:
        raise UserError(
            f"--prior-samples {prior_samples}: must be in 2..{MAX_PRIOR_SAMPLES} (codes drawn per primitive)"
        )
    return {"primitive": primitive, "primitives": source, "n_clusters": clusters, "prior_samples": prior_samples}


def _check_ignored(iterations, online: bool, fitted, init, scene: bool) -> None:
    """One line for an option that would be ignored (rather than ignoring it without a word)."""
    from primspace.model.latent import INFER_STARTS
    from primspace.predict import AUTO, DEFAULT_PREDICTOR, MIXTURE, PRIOR
    from primspace.predict.registry import GRADIENT, spec_for
    from primspace.train.starts import STARTS_FROM_FITTED

    if iterations is not None and not online:
        raise UserError("--iterations goes with --online (the iterations per arriving step)")
    start = init or DEFAULT_PREDICTOR
    if iterations is not None and spec_for(start).name != GRADIENT:
        raise UserError(
            f"--iterations is read by gradient inference (--init {', '.join(INFER_STARTS)}); --init {start} "
            "predicts each arriving step without iterations: drop --iterations"
        )
    readers = STARTS_FROM_FITTED + (AUTO, MIXTURE, PRIOR)
    if fitted is not None and not scene and init is not None and start not in readers:
        raise UserError(
            f"--fitted-data is read by auto, mixture, nearest and calibrated, and by prior; --init {start} does not "
            "read it"
        )


def _check_scene_flags(scene: bool, primitive, observed: dict, init, online: bool) -> None:
    """One line for flags that do not go with ``--scene``, and ``--scene`` without ``--primitive``."""
    if not scene:
        return
    amounts = [(option, text) for option, (text, _) in observed.items()]
    amounts += [(f"{option}-steps", steps) for option, (_, steps) in observed.items()]
    given = [name for name, value in (*amounts, ("--init", init), ("--online", online or None)) if value is not None]
    if given:
        raise UserError(f"--scene observes the first frame and the first joints only: do not give {', '.join(given)}")
    if primitive is None:
        raise UserError(
            "--scene needs --primitive P: the primitive to perform, a label name or an id (or 'cluster k' "
            "with --primitives clusters)"
        )


def _write_posterior(tmp: Path, prediction, dataset) -> None:
    """posterior.png: the prior's posterior over primitives against the observed fraction of the
    predicted motions (the fitted prior asked again, :func:`~primspace.predict.posterior.posterior_by_fraction`)."""
    from primspace.plots import plot_posterior, save_figure
    from primspace.predict.posterior import POSTERIOR_FRACTIONS, posterior_by_fraction

    data = dataset.subset(prediction.indices)
    predictor = getattr(prediction.predictor, "predictor_", None) or prediction.predictor  # auto: the chosen one
    curve = posterior_by_fraction(predictor, data, POSTERIOR_FRACTIONS)
    source = prediction.details["prior"]["primitives"]["source"]
    fig = plot_posterior(
        POSTERIOR_FRACTIONS,
        curve,
        prediction.details["primitives"],
        labels=data.labels,
        label_names=data.label_names,
        title=f"the prior's posterior over its primitives ({source})",
    )
    save_figure(fig, tmp / "posterior.png", writer=PREDICT_MARK)


def _chosen(prediction) -> str:
    """`` (prior, the lowest 3-fold error: mixture 0.013, prior 0.0012)`` for a predictor chosen by held-out
    evidence, else nothing."""
    selection = prediction.details.get("selection")
    if not selection:
        return ""
    errors = ", ".join(f"{name} {'-' if e is None else f'{e:.3g}'}" for name, e in selection["errors"].items())
    if not selection["folds"]:
        return f" ({selection['chosen']}, the one candidate of this task)"
    return f" ({selection['chosen']}, the lowest {selection['folds']}-fold error: {errors})"


def _summary_line(out: Path, result: dict, prediction, online: bool, judged: dict | None, frames: bool) -> str:
    """What ``primspace predict`` prints when it is done (``frames``: the data has frames)."""
    from primspace.act.scene_policy import SCENE_POLICY

    means = ", ".join(f"{k} {v:.4g}" for k, v in result["mean"].items() if v is not None)
    means = means or "every valid step was observed, no step left to score"
    seen = observed_text(prediction.observation, frames)
    line = f"wrote {out}: {result['n']} motions predicted from {seen}, init {prediction.init}{_chosen(prediction)}: {means}"
    if prediction.details.get("mode") == SCENE_POLICY:
        d = prediction.details
        line += f"; every motion as primitive {d['primitive']} ({d['name']}) of the {d['policy']['source']}"
    elif prediction.details.get("primitive") is not None:
        line += f"; every motion as primitive {prediction.details['primitive']}"
    if prediction.details.get("posterior_accuracy") is not None:
        line += f"; the posterior's top primitive is the label's for {prediction.details['posterior_accuracy']:.0%}"
    if online:
        o = prediction.details["online"]
        line += f"; online, {o['iterations']} iterations per step: {o['latency_ms_mean']:.1f} ms per step"
    if judged is not None:
        line += "; success " + ", ".join(f"{p} {r:.2f}" for p, r in judged["rates"].items())
    return line
