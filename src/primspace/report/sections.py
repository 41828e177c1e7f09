"""The report's sections, each written from an experiment directory's results files.

A section reads ``OUT/experiment.json``, ``OUT/results/*.json`` and the PNGs and GIFs of
``OUT/figures`` (through :mod:`primspace.results`, which imports no
experiment) and computes nothing:
no model is loaded, no data set is read, nothing is drawn or sampled. A section whose
results are absent adds nothing, or a note saying what is missing.
The closing sections (Appendix A, the environment) live in :mod:`primspace.report.appendices`,
the act experiment's in :mod:`primspace.report.act_section`; both are importable from here.
"""

from __future__ import annotations

from pathlib import Path

from primspace.report.act_section import act
from primspace.report.appendices import appendix_a, environment
from primspace.report.page import HtmlReport
from primspace.report.predict_tables import TASKS_TEXT, VERDICT_RULE, splits_tasks, task_tables
from primspace.results.calibration import calibration_table, calibration_verdict
from primspace.results.claims import check_claims, claims_table
from primspace.results.composite import bounds_table, composite_table, primitives_table, recall_table
from primspace.results.layout import (
    ANIMATION_RESULTS,
    IMAGE_STRIPS,
    INITIAL_CODES,
    PROBE_RESULTS,
    animation_file,
    figure_file,
    figures_dir,
    results_file,
)
from primspace.results.readers import read_meta, read_results
from primspace.results.tables import (
    failed_criteria_table,
    final_loss_table,
    inter_table,
    latent_table,
    outcome_spread_table,
    predict_error_table,
    probe_table,
    qualitative_check,
    scene_table,
    spread_table,
    success_table,
    tuning_table,
)

__all__ = [
    "summary",
    "claims",
    "data",
    "intra",
    "clustering",
    "success",
    "inter",
    "tuning",
    "latent_figures",
    "animations",
    "act",
    "appendix_a",
    "environment",
]


def summary(out_dir: Path, report: HtmlReport) -> None:
    """The paper's central result as we test it (intra), and failed runs."""
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
            "initialisation. (The paper's own sentences are checked one by one in the next section.) " + text,
            "good",
        )
    else:
        report.note(
            "The paper's central result, as we test it, does NOT hold in every case here (projection's final "
            "evaluation loss is not below both zero and random initialisation). " + text,
            "warn",
        )
    if results["failures"]:
        _failures(report, results["failures"], "run(s)", detail=True)


def claims(out_dir: Path, report: HtmlReport) -> None:
    """The paper's sentences, verbatim, with our verdict on each."""
    if all(r["verdict"] == "not run" for r in check_claims(out_dir)):
        return
    report.section("The paper's claims, checked")
    report.paragraph(
        "Each sentence is quoted verbatim from the paper (its abstract, Experimental Results and Summary); the "
        "paper gives no numbers for its curves, so the rule in the second column is our reading of it. The "
        "direction says which way a verdict other than holds goes: in the paper's favour (random-projection "
        "initialisation does better than the sentence says), against the paper (it does worse, or the effect is "
        "absent), or cannot be checked at this scale (the runs it needs are missing)."
    )
    columns, rows = claims_table(out_dir, codes=out_dir)
    report.table(columns, rows)


def data(out_dir: Path, report: HtmlReport) -> None:
    """The data set's summary (``results/data.json``, written when an experiment loads it)."""
    s = read_results(out_dir, "data")
    report.section("Data")
    if s is None:
        meta = read_meta(out_dir)
        report.note(
            f"No data summary here: results/{results_file(out_dir, 'data').name} is written when an experiment "
            "loads its data, and an older primspace did not write it. Re-run an experiment command with "
            f"--out {out_dir} (finished runs are skipped) to write it. Data file: {meta.get('data', '?')}.",
            "warn",
        )
        return
    report.paragraph(
        f"{s['n_samples']} samples, T = {s['length']} steps, J = {s['n_joints']} joints "
        f"({', '.join(s['joint_names'])}), images {('x'.join(map(str, s['image_shape'])) if s['image_shape'] else 'none')}; "
        f"file {s['path']}."
    )
    report.code(s["source"])
    if s["label_counts"]:
        report.table(["primitive", "samples"], list(s["label_counts"].items()))


def intra(out_dir: Path, report: HtmlReport) -> None:
    """Intra-primitive generalisation: the two convergence figures and the final losses."""
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
    report.figure(
        figure_file(out_dir, "intra_loss_fit"), "Loss while fitting θ and Z (the paper's first convergence figure)."
    )
    report.figure(
        figure_file(out_dir, "intra_loss_infer"),
        "Loss while inferring Z with θ frozen (the paper's second convergence figure).",
    )
    columns, rows = final_loss_table(results)
    report.table(columns, rows, "Final losses per run.")
    spread = spread_table(results, read_results(out_dir, PROBE_RESULTS))
    if spread is not None:
        report.table(
            *spread, "Spread over seeds (each seed its own split, weights and projection): mean ± sample std (ddof 1)."
        )
    outcomes = outcome_spread_table(read_results(out_dir, "clustering"), read_results(out_dir, "success"))
    if outcomes is not None:
        report.table(
            *outcomes,
            "Success rates and latent clustering over seeds (at the clustered q): mean ± sample std (ddof 1).",
        )


def calibration(out_dir: Path, report: HtmlReport) -> None:
    """Calibrated projection (beyond the paper): the ridge-mapped start against the raw projection."""
    results = read_results(out_dir, "intra")
    table = None if results is None else calibration_table(results)
    if table is None:
        return
    report.section("Calibrated projection (beyond the paper)")
    report.paragraph(
        "The paper starts a new sample's code at its projection P m. Its reason (Initialization of Latent Vectors, "
        "Appendix A) is what P keeps of the trajectory space: inner products in expectation (E[Pa·Pb] = a·b), so "
        'similar motions start at similar codes, and subspaces: "Moreover, under the assumption of motion '
        "primitives being close to linear subspaces in trajectory space, the projected primitives are also close to "
        "linear subspaces in latent space if latent dimension suffice.\" That the codes stay near P m is the paper's "
        'reading of its own inference result (Intra-primitive generalisation): "On the other hand, initialization '
        "with random linear projection yields good results already without any training, which means the initial "
        'distribution of projected points did not change much during the first part of the training." The '
        "movement below tests that reading: the fitted codes do move (5-7 % on the paper preset, 11-53 % on the "
        "smaller demo, LASA and wrist-sensor data; CHANGELOG.md, 0.5.0). Calibrated projection starts a new code at "
        "B P m + c instead: a ridge regression (with intercept, its strength chosen by leave-one-out on the training "
        "part) from the training samples' P m to their fitted codes, fitted at the end of projection's fit; same θ, "
        "same P. Movement and R² below are the projection fit's, on its training part (R² of P m: how well P m "
        "itself predicts the fitted codes; held-out R² of the map: out-of-fold)."
    )
    report.table(*table, "Eval-part loss at the start and the end of inference, mean ± sample std (ddof 1) over seeds.")
    ok, text = calibration_verdict(results)
    verdict = {
        True: "calibrated never loses (by more than 5%) to projection or zero",
        False: "calibrated loses in some runs",
        None: "cannot be checked",
    }[ok]
    report.paragraph(f"{verdict}: {text}.")


def clustering(out_dir: Path, report: HtmlReport) -> None:
    """Subspace clustering of the codes and of the raw trajectories."""
    results = read_results(out_dir, "clustering")
    if results is None:
        return
    report.section("Subspace clustering")
    report.paragraph(
        f"Affine low-rank subspace clustering (Q* = V P(Λ) Vᵀ, Ng–Jordan–Weiss spectral step on Q*∘Q*) of the "
        f"codes of all samples at q = {results['latent_dim']}, τ chosen for R² = {results['r2_target']} "
        "(the paper's setting), and of the raw joint trajectories (scaled to [-1, 1] per joint, flattened) with a "
        "τ sweep. Accuracy after Hungarian matching of clusters to primitives; NMI and ARI."
    )
    columns, rows = latent_table(results)
    report.table(columns, rows)
    report.figure(
        figure_file(out_dir, "latent_accuracy_vs_r2"),
        "Accuracy of clustering the codes when τ is chosen for other R² targets (dashed: the projection "
        "before training). With few points per primitive in q dimensions, high targets keep every component "
        "and the affinity degenerates towards the identity.",
    )
    for r in results["latent"]:
        name = (
            "latent_clustering_projection_initial" if r["codes"] == INITIAL_CODES else f"latent_clustering_{r['init']}"
        )
        report.figure(
            figure_file(out_dir, name),
            f"{r['init']} ({r['codes']}): affinity ordered by primitive, and the predicted cluster of each sample.",
        )
    for name in results["trajectory"]:
        report.figure(
            figure_file(out_dir, f"trajectory_sweep_{name}"),
            f"τ sweep on raw trajectories ({name}): R², rank and scores per τ.",
        )
        report.figure(
            figure_file(out_dir, f"trajectory_clustering_{name}"),
            f"Raw trajectories ({name}) clustered at the chosen τ.",
        )


def success(out_dir: Path, report: HtmlReport) -> None:
    """Success rates of the generated motions, and the criteria that failed."""
    results = read_results(out_dir, "success")
    if results is None:
        return
    report.section("Success rates of generated motions")
    report.paragraph(
        f"Eval-part codes (q = {results['latent_dim']}) decoded to joint trajectories and judged by the simulator "
        "(criteria in docs/simulator.md), per primitive. The paper judged grasp, push and pull by eye and reported "
        "0.8 / 0.9 / 0.86 (zero init) against 1.0 / 0.94 / 0.92 (projection init)."
    )
    if results["recorded"] is None:
        report.note("The recorded trajectories were not judged (the run failed).", "warn")
        return
    if results["recorded"]["overall"] < 1.0:
        report.note("Not every recorded trajectory passes the judge: the judge or the data is at fault.", "warn")
    columns, rows = success_table(results)
    report.table(columns, rows, "Fraction of successful motions per primitive.")
    columns, reasons = failed_criteria_table(results)
    if reasons:
        report.table(columns, reasons, "Criteria are defined in docs/simulator.md; a sample can fail several.")


def inter(out_dir: Path, report: HtmlReport) -> None:
    """Inter-primitive generalisation: the phase-2 loss over folds."""
    results = read_results(out_dir, "inter")
    if results is None:
        return
    report.section("Inter-primitive generalisation")
    report.paragraph(
        "Seven folds: θ and Z fitted on six primitives (phase 1), then on the seventh plus "
        f"{results['replay']:.0%} replay of the others (phase 2), q = {results['latent_dim']}."
    )
    report.figure(
        figure_file(out_dir, "inter_loss"),
        "Phase-2 loss, mean ± std over folds (the paper's inter-primitive figure; on the log axis the band stops at the lowest fold).",
    )
    columns, rows = inter_table(results)
    report.table(columns, rows)
    if results["failures"]:
        _failures(report, results["failures"], "fold run(s)")


def tuning(out_dir: Path, report: HtmlReport) -> None:
    """Fair baselines: each init's tuned setting and its loss beside the shared setting's."""
    results = read_results(out_dir, "tune")
    if results is None:
        return
    grid = results["grid"]
    report.section("Fair baselines: every init tuned")
    report.paragraph(
        f"Each init was tuned with the same budget on a validation part ({grid['validation_fraction']:.0%} of each "
        "primitive's fitted samples; the evaluation part never seen): layer time constants "
        f"{', '.join(str(tuple(t)) for t in grid['taus'])} x latent learning rate x "
        f"{', '.join(f'{f:.3g}' for f in grid['latent_lr_factor'])} of the preset's, {grid['epochs'][0]} + "
        f"{grid['epochs'][1]} epochs for all, at q = {results['latent_dim']}; the setting with the lowest mean "
        "validation loss was then used for the intra protocol. The headline comparisons use the shared setting "
        "(the paper's protocol); this table says whether a gap survives tuning."
    )
    columns, rows = tuning_table(results, read_results(out_dir, "intra"))
    report.table(columns, rows)
    if results["failures"]:
        _failures(report, results["failures"], "tuning run(s)")


def _failures(report: HtmlReport, failures: dict, what: str, detail: bool = False) -> None:
    """A warning naming the failed grid points (with their errors when ``detail``)."""
    named = (f"{k}: {v}" for k, v in failures.items()) if detail else failures
    report.note(f"{len(failures)} {what} failed: " + "; ".join(named), "warn")


def prediction(out_dir: Path, report: HtmlReport) -> None:
    """Predicting the rest of a motion: error (and success) against the observed fraction, per start and peer."""
    results = read_results(out_dir, "predict")
    if results is None:
        return
    report.section("Predicting the rest of a motion")
    report.paragraph(
        f"Each evaluation motion's first 10, 25 and 50 % are observed and the rest predicted, with θ of the projection "
        f"fit at q = {results['latent_dim']} frozen (docs/predict.md). primspace's starts: gradient inference on the "
        f"observed entries ({results['epochs']} epochs) from zero, projection, calibrated or nearest, or the mixture "
        "over the fitted codes (no gradient: its posterior mean, or its weighted ensemble conditioned on the observed "
        "entries when leave-one-out on the fitted demonstrations prefers it; 'mixture (posterior mean)' never "
        "conditions); each with the continuity correction. The peers on the same split: "
        "ProMP conditioning given the labels, one ProMP for all, the nearest fitted demonstration, the mean motion "
        "of the primitive (given the label); the ProMPs' noise chosen on the answer. MSE of the unobserved steps, "
        "mean ± sample std (ddof 1) over seeds"
        + (
            "; success as judged by the simulator (at 100 % nothing is left to predict)."
            if results.get("judged")
            else "."
        )
    )
    _predict_tables(report, results)
    report.figure(
        figure_file(out_dir, "predict_errors"), "Error of the unobserved steps against the observed fraction."
    )
    if results["failures"]:
        _failures(report, results["failures"], "prediction point(s)")


def _predict_tables(report: HtmlReport, results: dict) -> None:
    """The prediction grid's table, or from version 4 on its two tasks with their verdicts
    (:func:`primspace.report.predict_tables.task_tables`, as docs/predict.md shows them)."""
    if not splits_tasks(results):
        report.table(*predict_error_table(results))
        return
    report.paragraph(f"{TASKS_TEXT} {VERDICT_RULE}")
    for task in task_tables(results):
        report.subsection(task.title)
        report.table(task.columns, task.rows)
        report.paragraph(task.verdict)


def scene_only(out_dir: Path, report: HtmlReport) -> None:
    """Acting from the scene only: success (and error) per primitive, beside the mean motion and the reproduction."""
    results = read_results(out_dir, "scene")
    if results is None:
        return
    report.section("Acting from the scene only")
    report.paragraph(
        f"See the block, do the primitive: each evaluation sample gives only its first camera frame and its first "
        f"joints, and names the primitive as the cluster of the fitted codes whose majority label is its own; the "
        f"code is searched inside that cluster's affine subspace ({results['epochs']} epochs, θ of the projection fit "
        f"at q = {results['latent_dim']} frozen) and decoded whole (docs/predict.md). Beside it, on the same samples: "
        "the mean motion of the primitive's fitted demonstrations (given the label) and the same run's codes inferred "
        "from the whole motion (the reproduction). MSE of the steps after the first (scaled units), mean ± sample std "
        "(ddof 1) over seeds" + ("; success as judged by the simulator." if results.get("judged") else ".")
    )
    columns, rows = scene_table(results)
    report.table(columns, rows)
    if results["failures"]:
        _failures(report, results["failures"], "scene point(s)")


def composite(out_dir: Path, report: HtmlReport) -> None:
    """Long demonstrations: held-out loss, boundaries and labels found from code sequences."""
    results = read_results(out_dir, "composite")
    if results is None:
        return
    report.section("Long demonstrations: sequences of codes")
    report.paragraph(
        "The paper's next step: “To model more complex behaviours composed of many consecutive primitives, instead of "
        "using a single latent vector z of fixed dimension usually a sequence of such vectors is used.” One code per "
        f"window of {results['window']} steps; the codes of held-out demonstrations are inferred with θ frozen, then "
        "segmented (change points) and labelled (affine subspace clustering of segment codes) without labels "
        "(docs/sequences.md)."
    )
    columns, rows = composite_table(results)
    report.table(
        columns,
        rows,
        "primspace per init, then its peers on the raw scaled joints (peer: rows; "
        "ruptures, hmmlearn), the same held-out demonstrations and scores; mean ± sample std (ddof 1) over seeds.",
    )
    single = primitives_table(results)
    if single is not None:
        report.table(
            *single,
            "A model of single primitives segments the same held-out demonstrations: by synthesis "
            "(the partition it generates best) and by surprise (where its prediction of the next steps "
            "fails); the bound gives each found segment its nearest template's true primitive.",
        )
    _composite_bounds(results, report)
    for phase in ("fit", "infer"):
        report.figure(figure_file(out_dir, f"composite_loss_{phase}"), f"Loss per epoch ({phase}), per init.")
    for path in sorted(figures_dir(out_dir).glob("composite_timeline_*.png")):
        report.figure(
            path,
            "Held-out demonstrations: the heat map shows code values per window (window codes) or "
            "the scaled joints per step (synthesis, surprise); true (solid) and found (dashed) boundaries, "
            "true and found labels (found colours are cluster ids).",
        )
    if results["failures"]:
        _failures(report, results["failures"], "run(s)")


def _composite_bounds(results: dict, report: HtmlReport) -> None:
    """The upper bounds on the true segments, and which primitives a classifier confuses."""
    bounds, recall = bounds_table(results), recall_table(results)
    if bounds is None:
        return
    report.paragraph(
        "Upper bounds, on the true segments of the same held-out demonstrations: classifiers given the labels "
        "(cross-validated, per-step accuracy) and the clustering without labels, from the raw joints, the joints minus "
        "each segment's start pose, and each run's window codes (their mean over the segment, as primspace labels "
        "segments, or their trajectory through it). A high supervised accuracy with a low unsupervised one means "
        "the primitives can be told apart and the method does not."
    )
    report.table(*bounds)
    if recall is not None:
        report.table(*recall, "Recall of each primitive by the logistic regression, mean over seeds.")


def latent_figures(out_dir: Path, report: HtmlReport) -> None:
    """The latent-encoding figures and the Appendix B reconstructions, as drawn."""
    figs = sorted(figures_dir(out_dir).glob("latent_pca*.png")) + sorted(
        figures_dir(out_dir).glob("reconstruction_*.png")
    )
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
            caption = (
                "Generated (dashed, lower frames) against recorded (solid, upper frames) — the paper's Appendix B."
            )
        report.figure(fig, caption)
        if fig.name == "latent_pca2d.png":
            _probe(out_dir, report)


def _probe(out_dir: Path, report: HtmlReport) -> None:
    """The latent-encoding figure as numbers: the linear probe's table (``results/probe.json``)."""
    results = read_results(out_dir, PROBE_RESULTS)
    if results is None:
        return
    report.paragraph(
        "The same structure as a number: the cross-validated R² of a ridge regression from the codes to the "
        f"factors that generated each motion ({', '.join(results['factor_names'])}), fitted within each primitive "
        "and averaged over primitives (weighted by samples); for the fitted codes (train part), the inferred codes "
        "(eval part, θ frozen) and the initial codes before any training (P m for projection). 1: the factors are a "
        "linear function of the codes; 0: no better than each primitive's mean (primspace.probe)."
    )
    columns, rows = probe_table(results)
    report.table(columns, rows, "Linear probe of the codes.")


def animations(out_dir: Path, report: HtmlReport) -> None:
    """One animated GIF per primitive (``results/intra_animation.json`` names them), the
    ones drawn; a missing GIF is left out."""
    results = read_results(out_dir, ANIMATION_RESULTS)
    shown = [a for a in (results or {}).get("animations", []) if animation_file(out_dir, a["name"]).exists()]
    if not shown:
        return
    report.section("Motions, animated")
    report.paragraph(
        "One evaluation sample per primitive, from the run the reconstructions above come from. Camera panels "
        "(left to right, where present): the recorded frames, the frames the code generates, and the simulator "
        "replaying the generated joints (the block moved as the success judge sees it). Right: every joint, "
        "recorded (solid) and generated (dashed), with a cursor at the frame's time. Time is subsampled to at most "
        f"{results['max_frames']} frames, each shown for {results['frame_ms'] / 1000:g} s (not real time)."
    )
    for a in shown:
        panels = ", ".join(a.get("panels", [])) or "no camera frames"
        report.figure(animation_file(out_dir, a["name"]), f"{a['title']}. Panels: {panels}.")
    strips = figure_file(out_dir, IMAGE_STRIPS)
    if strips.exists():
        report.figure(strips, "The same samples as stills: generated frames under recorded frames, per primitive.")
