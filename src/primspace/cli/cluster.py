"""The ``cluster`` command: affine low-rank subspace clustering of a data set or codes."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Optional

import typer

from primspace.errors import UserError, first_line

from primspace.cli.app import app
from primspace.cli.options import configure_threads, echo_json, threads_option


# ====================================================================== clustering


class ClusterAffinity(str, Enum):
    squared = "squared"
    abs = "abs"


class ClusterAutoCriterion(str, Enum):
    relative_eigengap = "relative_eigengap"
    eigengap = "eigengap"
    stability = "stability"


class ClusterSpectral(str, Enum):
    auto = "auto"
    dense = "dense"
    implicit = "implicit"


@app.command("cluster")
def cluster_command(
    src: Path = typer.Argument(
        ...,
        metavar="DATA",
        help="A MotionDataset .h5 (raw trajectories: joints scaled to [-1, 1], flattened), an (N, q) .npy of "
        "latents, or a run directory (its codes, scored with the labels of its samples in its data file).",
    ),
    k: Optional[int] = typer.Option(
        None, "--primitives", "-k", help="Number of primitives K: the clusters to find (required)."
    ),
    k_deprecated: Optional[int] = typer.Option(None, "--k", hidden=True, help="Deprecated name of --primitives."),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (labels.csv, result.json, clustering.png)."),
    tau: Optional[float] = typer.Option(None, "--tau", help="The paper's tau, absolute (> 0)."),
    tau_relative: Optional[float] = typer.Option(
        None, "--tau-relative", help="Scale-free tau: tau = R / sigma_1^2 (keeps sigma_k / sigma_1 > 1/sqrt(R))."
    ),
    r2: Optional[str] = typer.Option(
        None,
        "--r2",
        metavar="TARGET|auto",
        help="Smallest tau whose R^2 of Z ~ Z Q* reaches this target in (0, 1) (default 0.99); "
        "'auto': the target of the R^2 grid that --auto-criterion prefers, without labels.",
    ),
    auto_criterion: ClusterAutoCriterion = typer.Option(
        ClusterAutoCriterion.relative_eigengap,
        "--auto-criterion",
        help="With --r2 auto: eigengap of the normalised affinity at k relative to 1 - lambda_{k+1} (default), "
        "the plain eigengap, or label stability across subsamples.",
    ),
    linear: bool = typer.Option(False, "--linear", help="Linear subspaces (no ones row) instead of affine."),
    affinity: ClusterAffinity = typer.Option(ClusterAffinity.squared, help="W = Q*^2 (scales) or |Q*| (dense only)."),
    ones_weight: float = typer.Option(1.0, help="Value of the appended ones row (affine)."),
    spectral: ClusterSpectral = typer.Option(
        ClusterSpectral.auto, help="Spectral step: dense n x n, implicit, or auto by n."
    ),
    n_init: int = typer.Option(20, help="k-means restarts."),
    seed: int = typer.Option(0, help="Random seed (k-means; same seed, same labels)."),
    labels: Optional[Path] = typer.Option(
        None, "--labels", help="(N,) integer .npy of true labels (-1 = unknown) for scoring."
    ),
    do_sweep: bool = typer.Option(False, "--sweep", help="Also print and save R^2, rank and scores over a tau grid."),
    sweep_taus: Optional[str] = typer.Option(
        None, "--sweep-taus", help="Comma-separated absolute taus for --sweep (default: R^2 targets 0.5 ... 0.9999)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result JSON instead of text."),
    overwrite: bool = typer.Option(False, help="Replace a non-empty OUT directory."),
) -> None:
    """Affine low-rank subspace clustering (paper, Background): labels, scores, figure."""
    from primspace.cluster.outputs import check_output_directory
    from primspace.files import check_outside_inputs

    k, k_flag = _primitives_option(k, k_deprecated)
    check_outside_inputs(out, (src, labels))
    check_output_directory(out, overwrite)
    r2_target = _parse_r2(r2)
    _check_cluster_options(k, tau, tau_relative, r2_target, ones_weight, n_init, k_flag)
    grid = _parse_float_list(sweep_taus, "--sweep-taus") if sweep_taus else None
    points = _points(src, labels)
    if k > points.X.shape[0]:
        raise UserError(f"{k_flag} {k} exceeds the {points.X.shape[0]} samples in {src}")
    options = {
        "affine": not linear,
        "tau": tau,
        "tau_relative": tau_relative,
        "r2_target": r2_target,
        "auto_criterion": auto_criterion.value,
        "affinity": affinity.value,
        "ones_weight": ones_weight,
        "spectral": spectral.value,
        "n_init": n_init,
        "random_state": seed,
    }
    result = _cluster(src, points, k, options, do_sweep, grid)
    record = {"input": str(src), "points": points.description, **result.to_dict()}
    _write_outputs(out, overwrite, src, result, record, points.samples)
    if as_json:
        echo_json(record)
        return
    _print_summary(out, result)


def _points(src: Path, labels: Optional[Path]):
    """The points: a data file's trajectories, an ``.npy`` of codes, or a run's codes (a run
    directory, or the ``latents.npy`` in one) numbered by its samples' indices in the data
    file and labelled from it (``--labels``: one label per code, in the run's order)."""
    from primspace.cluster.inputs import ClusterPoints, load_points, read_labels

    maybe_run = src.is_dir() or src.name == "latents.npy"  # cheap: only then read what a run is
    if maybe_run:
        from primspace.train.rundir import CONFIG_NAME, LATENTS_NAME

        run_dir = src if src.is_dir() else src.parent if src.name == LATENTS_NAME else None
        maybe_run = run_dir is not None and (run_dir / CONFIG_NAME).is_file()
    if not maybe_run:
        return load_points(src, labels)
    from primspace.train import load_run
    from primspace.train.rundata import load_fitted_data

    trained = load_run(run_dir)
    X = trained.latents.astype("float64")
    true, names, whence = None, None, ""
    if labels is not None:
        true = read_labels(labels, len(X))
    elif trained.data_path is not None and Path(trained.data_path).is_file():
        fitted = load_fitted_data(trained)  # checked: the run's own samples, in its order
        if fitted.labels is not None:
            true, names, whence = fitted.labels.astype("int64"), list(fitted.label_names), f", labels of {fitted.path}"
    else:
        typer.echo(
            f"note: run {run_dir} has no data file to read labels from ({trained.data_path or 'none recorded'}): "
            "clustered without scores (give --labels)",
            err=True,
        )
    description = f"codes of run {run_dir}: {X.shape[0]} x {X.shape[1]}, numbered by the data file's index{whence}"
    return ClusterPoints(
        X=X, labels=true, label_names=names, path=src, description=description, samples=trained.indices
    )


def _cluster(src: Path, points, k: int, options: dict, do_sweep: bool, grid):
    """The pipeline on the loaded points; the estimator's ValueErrors as one-line errors."""
    from primspace.cluster import LowRankSubspaceClustering, cluster_points

    sweep_param = "tau" if grid is not None else "r2_target" if do_sweep else None
    try:
        return cluster_points(
            points.X,
            LowRankSubspaceClustering(k, **options),
            labels_true=points.labels,
            label_names=points.label_names,
            sweep_param=sweep_param,
            sweep_values=grid,
        )
    except ValueError as exc:  # parameter / data problems the estimator found
        raise UserError(f"{src}: {first_line(exc)}") from None


def _write_outputs(out: Path, overwrite: bool, src: Path, result, record: dict, samples=None) -> None:
    """``labels.csv`` (``samples``: each point's index in the data file; default the row),
    ``result.json``, ``clustering.png`` (and the sweep's files), atomically."""
    from primspace.cluster import clustering_figure, sweep_figure
    from primspace.cluster.outputs import (
        CLUSTER_OUTPUT,
        atomic_directory,
        write_json,
        write_labels_csv,
        write_sweep_csv,
    )
    from primspace.plots import save_figure

    n, scores = result.n_samples, result.scores
    shown = "" if result.figure_indices.size == n else f" ({result.figure_indices.size} of {n} samples)"
    acc = "" if scores is None or scores["accuracy"] is None else f", accuracy {scores['accuracy']:.3f}"
    figure = clustering_figure(
        result, title=f"{src.name}: tau = {result.tau:.3g}, R^2 = {result.r2:.4f}, rank {result.rank}{acc}{shown}"
    )
    with atomic_directory(out, overwrite) as tmp:
        write_labels_csv(tmp / "labels.csv", result.labels, result.labels_true, samples)
        write_json(tmp / "result.json", record)
        save_figure(figure, tmp / "clustering.png", writer=CLUSTER_OUTPUT.command)
        if result.sweep is not None:
            write_sweep_csv(tmp / "sweep.csv", result.sweep)
            write_json(tmp / "sweep.json", record["sweep"])
            save_figure(
                sweep_figure(result, title=f"{src.name}: tau sweep"), tmp / "sweep.png", writer=CLUSTER_OUTPUT.command
            )


def _print_summary(out: Path, result) -> None:
    if result.sweep is not None:
        typer.echo(_format_sweep(result.sweep))
    typer.echo(
        f"{result.n_samples} samples x {result.n_features} features -> {result.n_clusters} clusters: "
        f"tau {result.tau:.4g} (relative {result.tau_relative:.4g}), R^2 {result.r2:.4f}, rank {result.rank}, "
        f"spectral {result.spectral_method}, {result.seconds:.2f} s"
    )
    if result.auto is not None:
        auto = result.auto
        scores = ", ".join(
            f"{g:g}: " + ("-" if v is None else f"{v:.4g}") for g, v in zip(auto["grid"], auto["scores"])
        )
        typer.echo(f"tau chosen without labels by {auto['criterion']}: R^2 target {auto['r2_target']:g} ({scores})")
    scores = result.scores
    if scores is not None:
        if scores["accuracy"] is None:
            typer.echo("no sample has a known true label: nothing scored")
        else:
            typer.echo(
                f"accuracy {scores['accuracy']:.4f}  NMI {scores['nmi']:.4f}  ARI {scores['ari']:.4f}  "
                f"({scores['n_scored']} scored, {scores['n_ignored']} with unknown label)"
            )
    typer.echo(
        f"wrote {out}/: labels.csv, result.json, clustering.png"
        + (", sweep.csv, sweep.json, sweep.png" if result.sweep else "")
    )


def _primitives_option(k: Optional[int], deprecated: Optional[int]) -> tuple[int, str]:
    """``--primitives`` (``-k``) or its deprecated name ``--k``, and the flag to name in errors."""
    if k is not None and deprecated is not None:
        raise UserError("give --primitives (-k) once; --k is its deprecated name")
    if k is None and deprecated is None:
        raise UserError("missing option --primitives K (-k K): the number of primitives to find")
    return (k, "--primitives") if k is not None else (deprecated, "--k")


def _check_cluster_options(k, tau, tau_relative, r2, ones_weight, n_init, k_flag: str = "--primitives") -> None:
    if k < 1:
        raise UserError(f"{k_flag} must be at least 1, got {k}")
    given = [name for name, v in (("--tau", tau), ("--tau-relative", tau_relative), ("--r2", r2)) if v is not None]
    if len(given) > 1:
        raise UserError(f"give at most one of --tau, --tau-relative, --r2; got {' and '.join(given)}")
    for name, value in (("--tau", tau), ("--tau-relative", tau_relative), ("--ones-weight", ones_weight)):
        if value is not None and not (value > 0 and value != float("inf")):
            raise UserError(f"{name} must be a positive number, got {value}")
    if r2 is not None and r2 != "auto" and not 0 < r2 < 1:
        raise UserError(f"--r2 must lie in (0, 1), got {r2}")
    if n_init < 1:
        raise UserError(f"--n-init must be at least 1, got {n_init}")


def _parse_r2(text: str | None) -> float | str | None:
    """``--r2``: None, ``"auto"`` or a number (its range is checked with the other options)."""
    if text is None or text.strip().lower() == "auto":
        return None if text is None else "auto"
    try:
        return float(text)
    except ValueError:
        raise UserError(f"--r2 must be a number in (0, 1) or 'auto', got {text!r}") from None


def _parse_float_list(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UserError(f"{option} must be comma-separated numbers, got {text!r}") from None
    if not values or any(not (v > 0 and v != float("inf")) for v in values):
        raise UserError(f"{option} must list positive numbers, got {text!r}")
    return values


def _format_sweep(rows: list[dict]) -> str:
    def f(v, spec):
        width = int(spec.split(".")[0].rstrip("df"))
        return "-".rjust(width) if v is None else format(v, spec)

    grid = rows[0]["grid"] if rows else "tau"
    head = f"  {grid:>12} {'tau':>10} {'tau_rel':>10} {'R^2':>8} {'rank':>5} {'accuracy':>9} {'NMI':>7} {'ARI':>7}"
    lines = ["tau sweep (one SVD):", head]
    for r in rows:
        lines.append(
            f"  {r['value']:>12.6g} {f(r.get('tau'), '10.4g')} {f(r.get('tau_relative'), '10.4g')} "
            f"{f(r.get('r2'), '8.4f')} {f(r.get('rank'), '5d')} {f(r.get('accuracy'), '9.4f')} "
            f"{f(r.get('nmi'), '7.4f')} {f(r.get('ari'), '7.4f')}"
        )
    return "\n".join(lines)


# ===================================================================== segmentation

#: ``primspace segment``'s output directory.
SEGMENT_FILES = ("segments.csv", "step_labels.npy", "result.json", "timeline.png")


class SegmentOffset(str, Enum):
    auto = "auto"
    fade = "fade"
    translate = "translate"


class SegmentMethod(str, Enum):
    """``primspace.segmentation.METHODS``; the default is ``DEFAULT_METHOD`` (a test keeps them equal:
    not imported here, so that the command line starts without scikit-learn)."""

    synthesis = "synthesis"
    surprise = "surprise"
    windows = "windows"


_SEGMENT_RUN = typer.Argument(
    ...,
    help="synthesis, surprise: a run of single primitives (one code per "
    "demonstration); windows: a run trained with --code-window on DATA (fit or infer).",
)
_SEGMENT_METHOD = typer.Option(
    None,
    "--method",
    show_default=False,
    help="synthesis (default): the partition into segments that the "
    "single-primitive run generates best; surprise: where its prediction of the next steps fails; windows (the default "
    "for a run trained with --code-window): change points of the run's window codes (docs/sequences.md).",
)
_STEPS = "surprise, synthesis: the {} steps of a primitive in DATA (default {} x the run's T)."


@app.command("segment")
def segment_command(
    run: Path = _SEGMENT_RUN,
    data: Path = typer.Argument(
        ..., metavar="DATA", help="Long demonstrations (with lengths; windows: the run's data file)."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output directory (segments.csv, step_labels.npy, result.json, timeline.png)."
    ),
    method: Optional[SegmentMethod] = _SEGMENT_METHOD,
    primitives: Optional[int] = typer.Option(
        None, "--primitives", "-k", help="Number of primitives K (default: the data's label names)."
    ),
    tolerance: Optional[int] = typer.Option(
        None,
        "--tolerance",
        help="Steps within which a found boundary matches a true one (default: the code window; surprise, synthesis: 8).",
    ),
    min_steps: Optional[int] = typer.Option(None, "--min-steps", help=_STEPS.format("fewest", "0.4")),
    max_steps: Optional[int] = typer.Option(None, "--max-steps", help=_STEPS.format("most", "0.85")),
    infer_epochs: int = typer.Option(
        0,
        "--infer-epochs",
        help="surprise, synthesis: infer each segment's code with "
        "θ frozen for this many epochs and label by those codes (0: its nearest "
        "template's code; docs/sequences.md measures both).",
    ),
    offset: SegmentOffset = typer.Option(
        SegmentOffset.auto,
        "--offset",
        help="surprise, synthesis: how a primitive "
        "begun where the last ended meets the model's: fade (the start offset fades "
        "out), translate (kept throughout), auto (the one that explains DATA better).",
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an earlier segment output in OUT."),
    threads: Optional[int] = threads_option(),
) -> None:
    """Find the primitives in long demonstrations: boundaries (change points of a run's window
    codes, or the segments a single-primitive run generates best) and labels (affine subspace
    clustering of segment codes); scored against the data's step_segments / step_labels when it has them."""
    import numpy as np

    from primspace.cluster.outputs import OutputKind, atomic_directory, check_output_directory, write_json
    from primspace.data import MotionDataset
    from primspace.files import check_outside_inputs
    from primspace.train import load_run

    kind = OutputKind("primspace segment", SEGMENT_FILES, frozenset({"window", "boundaries", "scores"}))
    check_outside_inputs(out, (run, data))
    check_output_directory(out, overwrite, kind)
    configure_threads(threads)
    trained = load_run(run)
    method = segment_method(method, trained)
    _check_segment_options(method, min_steps, max_steps, offset, infer_epochs, tolerance)
    ds = MotionDataset.load(data)
    segment = _segment_windows if method is SegmentMethod.windows else _segment_by_primitives
    samples, held, result, scores, window, k = segment(
        trained, ds, run, data, primitives, tolerance, (min_steps, max_steps, offset.value, infer_epochs), method.value
    )
    record = {
        "run": str(run),
        "data": str(data),
        "method": method.value,
        "window": window,
        "n_primitives": k,
        "samples": samples.tolist(),
        "boundaries": [b.tolist() for b in result.boundaries],
        "scores": scores,
        "note": result.note,
    }
    record |= {k: result.chosen[k] for k in ("offset", "threshold", "codes") if k in result.chosen}
    with atomic_directory(out, overwrite, kind) as tmp:
        _write_segments(tmp / "segments.csv", samples, result)
        np.save(tmp / "step_labels.npy", result.padded_step_labels(held.length))
        _timeline(tmp / "timeline.png", trained, held, result, window, method.value)
        write_json(tmp / "result.json", record)
    typer.echo(_segment_summary(scores, len(held)))
    typer.echo(f"wrote {out}")


def segment_method(method: Optional[SegmentMethod], trained) -> SegmentMethod:
    """``--method``, or its default: ``primspace.segmentation.DEFAULT_METHOD`` (synthesis), and
    windows for a run trained with --code-window (the one method such a run can use)."""
    from primspace.segmentation import DEFAULT_METHOD

    if method is not None:
        return method
    return SegmentMethod.windows if trained.model_config.code_window is not None else SegmentMethod(DEFAULT_METHOD)


def _check_segment_options(method: SegmentMethod, min_steps, max_steps, offset, infer_epochs: int, tolerance) -> None:
    if method is SegmentMethod.windows and (
        min_steps is not None or max_steps is not None or offset is not SegmentOffset.auto or infer_epochs
    ):
        raise UserError(
            "--min-steps, --max-steps, --offset and --infer-epochs apply to --method surprise and synthesis"
        )
    if infer_epochs < 0:
        raise UserError(f"--infer-epochs {infer_epochs}: must be at least 0")
    if tolerance is not None and tolerance < 0:
        raise UserError(f"tolerance (--tolerance) must be at least 0 steps, got {tolerance}")


def _primitives(held, primitives: Optional[int], data: Path) -> int:
    if primitives is None and not held.label_names:
        raise UserError(f"{data}: no label names to count the primitives; pass --primitives K")
    if primitives is not None and primitives < 1:
        raise UserError(f"--primitives {primitives}: must be at least 1")
    return primitives or len(held.label_names)


def _segment_windows(trained, ds, run: Path, data: Path, primitives, tolerance, _steps, _method):
    """Change points of the run's window codes (the run's own samples of ``ds``)."""
    from primspace.experiments.composite.experiment import segment_codes
    from primspace.train import check_run_data

    window = trained.model_config.code_window
    if window is None:
        raise UserError(
            f"{run}: the run has one code per sequence; --method windows needs a run trained with "
            "--code-window (or use --method surprise or synthesis)"
        )
    check_run_data(trained, ds)
    held = ds.subset(trained.indices)
    k = _primitives(held, primitives, data)
    result, scores = segment_codes(
        trained.latents, held, window, trained.model_config.latent_dim, tolerance=tolerance, n_primitives=k
    )
    return trained.indices, held, result, scores, window, k


def _segment_by_primitives(trained, ds, run: Path, data: Path, primitives, tolerance, steps, method: str):
    """The segments the single-primitive run generates best, or where its prediction fails
    (every sample of ``ds``)."""
    import numpy as np

    from primspace.segmentation import segmentation_scores
    from primspace.segmentation.surprise import segment_by_surprise
    from primspace.segmentation.synthesis import segment_by_synthesis
    from primspace.sim.composite import transition_steps

    from primspace.progress import stage

    k = _primitives(ds, primitives, data)
    segment = segment_by_surprise if method == "surprise" else segment_by_synthesis
    with stage(f"segment: {len(ds)} demonstrations by {method}"):
        result = segment(trained, ds, k, min_steps=steps[0], max_steps=steps[1], offset=steps[2], infer_epochs=steps[3])
    scores = segmentation_scores(result, ds, 8 if tolerance is None else tolerance, transition_steps(ds))
    return np.arange(len(ds)), ds, result, scores, 1, k


def _write_segments(path: Path, samples, result) -> None:
    """One row per segment: the sample (data index), its segment number, steps, label."""
    from collections import Counter

    from primspace.files import atomic_write_text

    lines, seen = ["sample,segment,start,stop,label"], Counter()
    for i, a, b, lab in zip(result.segment_sample, result.segment_start, result.segment_stop, result.segment_labels):
        lines.append(f"{int(samples[i])},{seen[int(i)]},{int(a)},{int(b)},{int(lab)}")
        seen[int(i)] += 1
    atomic_write_text(path, "\n".join(lines) + "\n")


def _timeline(path: Path, trained, held, result, window: int, method: str, shown: int = 4) -> None:
    """The first ``shown`` demonstrations' code sequences (synthesis: scaled joints) with true and found boundaries."""
    import numpy as np

    from primspace.plots import save_figure
    from primspace.plots.sequences import plot_code_timeline
    from primspace.segmentation import boundaries_from_segments

    n = min(shown, len(held))
    if method != "windows":
        codes = trained.scaler.transform(np.asarray(held.motor[:n], dtype=np.float64))
        what = f"{trained.init}: joints (scaled), segments by {method}"
    else:
        codes = trained.latents[:n].reshape(n, -1, trained.model_config.latent_dim)
        what = f"{trained.init}: code sequences (q = {trained.model_config.latent_dim}, W = {window})"
    lengths = held.lengths[:n] if held.lengths is not None else np.full(n, held.length)
    truth = held.step_labels[:n] if held.step_labels is not None else np.full((n, held.length), -1)
    true_bounds = (
        boundaries_from_segments(held.step_segments[:n], lengths) if held.step_segments is not None else [[]] * n
    )
    fig = plot_code_timeline(
        codes,
        window,
        lengths,
        truth,
        result.padded_step_labels(held.length)[:n],
        true_bounds,
        result.boundaries[:n],
        label_names=list(held.label_names),
        title=what,
    )
    save_figure(fig, path, writer="primspace segment")


def _segment_summary(scores: dict, n: int) -> str:
    if "boundary" not in scores:
        return f"{n} demonstrations: {scores['segments_found']} segments found"
    b = scores["boundary"]
    return (
        f"{n} demonstrations: {scores['segments_found']} segments found, {scores['segments_true']} true; "
        f"boundary F1 {b['f1']:.3f} (precision {b['precision']:.3f}, recall {b['recall']:.3f}, "
        f"within {scores['tolerance']} steps"
        + (
            f"; {scores['boundary_transition']['f1']:.3f} within them of the transition"
            if "boundary_transition" in scores
            else ""
        )
        + f"); step labelling accuracy {scores['accuracy']:.3f}"
    )
