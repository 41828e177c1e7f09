"""The ``cluster`` command: affine low-rank subspace clustering of a data set or codes."""

from __future__ import annotations

from dataclasses import replace
from enum import Enum
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import allow_unfinished_option, check_finished, echo_json
from primspace.utils.errors import UserError, first_line


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
    k: int | None = typer.Option(
        None, "--primitives", "-k", help="Number of primitives K: the clusters to find (required)."
    ),
    k_deprecated: int | None = typer.Option(None, "--k", hidden=True, help="Deprecated name of --primitives."),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (labels.csv, result.json, clustering.png)."),
    tau: float | None = typer.Option(None, "--tau", help="The paper's tau, absolute (> 0)."),
    tau_relative: float | None = typer.Option(
        None, "--tau-relative", help="Scale-free tau: tau = R / sigma_1^2 (keeps sigma_k / sigma_1 > 1/sqrt(R))."
    ),
    r2: str | None = typer.Option(
        None,
        "--r2",
        metavar="TARGET",
        help="Smallest tau whose R^2 of Z ~ Z Q* reaches this target in (0, 1); "
        "'auto': the target of the R^2 grid that --auto-criterion prefers, without labels; "
        "'select' (default): 0.99, 0.7 and the 'auto' target compared by their stability across "
        "independent halves of the points, without labels.",
    ),
    auto_criterion: ClusterAutoCriterion = typer.Option(
        ClusterAutoCriterion.relative_eigengap,
        "--auto-criterion",
        help="With --r2 auto or select: eigengap of the normalised affinity at k relative to 1 - lambda_{k+1} (default), "
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
    labels: Path | None = typer.Option(
        None, "--labels", help="(N,) integer .npy of true labels (-1 = unknown) for scoring."
    ),
    do_sweep: bool = typer.Option(False, "--sweep", help="Also print and save R^2, rank and scores over a tau grid."),
    sweep_taus: str | None = typer.Option(
        None, "--sweep-taus", help="Comma-separated absolute taus for --sweep (default: R^2 targets 0.5 ... 0.9999)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the result JSON instead of text."),
    overwrite: bool = typer.Option(False, help="Replace a non-empty OUT directory."),
    allow_unfinished: bool = allow_unfinished_option(),
) -> None:
    """Affine low-rank subspace clustering (paper, Background): labels, scores, figure."""
    from primspace.cluster.outputs import CLUSTER_OUTPUT
    from primspace.utils.files import check_outside_inputs
    from primspace.utils.folders import atomic_directory, check_output_directory
    from primspace.utils.seeds import check_seed, library_seed

    check_seed(seed, "--seed")
    k, k_flag = _primitives_option(k, k_deprecated)
    check_outside_inputs(out, (src, labels))
    check_output_directory(out, overwrite, CLUSTER_OUTPUT)
    r2_target = _parse_r2(r2)
    _check_cluster_options(k, tau, tau_relative, r2_target, ones_weight, n_init, k_flag)
    grid = _parse_float_list(sweep_taus, "--sweep-taus") if sweep_taus else None
    with atomic_directory(out, overwrite, CLUSTER_OUTPUT) as tmp:  # checked and locked before any work
        points = _points(src, labels, allow_unfinished)
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
            "random_state": library_seed(seed),
        }
        result = _cluster(src, points, k, options, do_sweep, grid)
        note = _codes_note(src, points, k, options, result)
        record = {"input": str(src), "points": points.description, **result.to_dict()}
        if note is not None:
            record["note"] = note
        _write_outputs(tmp, src, result, record, points.samples)
    if as_json:
        echo_json(record)
        return
    _print_summary(out, result)
    if note is not None:
        typer.echo(note, err=True)


#: Codes of at most this many samples are compared with their raw trajectories.
RAW_COMPARISON_MAX_SAMPLES = 5000


def _codes_note(src: Path, points, k: int, options: dict, result) -> str | None:
    """For a run's codes: why they may cluster below the raw trajectories of the same samples
    (clustered with the same settings when the codes are scored), in one line, or None."""
    from primspace.cluster.advice import codes_note

    if points.samples is None:  # not a run's codes
        return None
    codes, raw = _accuracy(result), None
    if points.raw is not None and codes is not None and points.X.shape[0] <= RAW_COMPARISON_MAX_SAMPLES:
        raw = _accuracy(_cluster(src, replace(points, X=points.raw), k, options, False, None))
    return codes_note(
        points.X.shape[0], points.X.shape[1], k, affine=options["affine"], codes_accuracy=codes, raw_accuracy=raw
    )


def _accuracy(result) -> float | None:
    return None if result.scores is None else result.scores["accuracy"]


def _points(src: Path, labels: Path | None, allow_unfinished: bool = False):
    """The points: a data file's trajectories, an ``.npy`` of codes, or a run's codes (a run
    directory, or the ``latents.npy`` in one) numbered by its samples' indices in the data
    file and labelled from it (``--labels``: one label per code, in the run's order)."""
    from primspace.cluster.inputs import ClusterPoints, load_points, read_labels, trajectory_matrix

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
    check_finished(trained, allow_unfinished)
    X = trained.latents.astype("float64")
    true, names, whence, raw = None, None, "", None
    if labels is not None:
        true = read_labels(labels, len(X))
    if trained.data_path is not None and Path(trained.data_path).is_file():
        fitted = load_fitted_data(trained)  # checked: the run's own samples, in its order
        raw = trajectory_matrix(fitted.motor)
        if fitted.labels is not None and labels is None:
            true, names, whence = fitted.labels.astype("int64"), list(fitted.label_names), f", labels of {fitted.path}"
    elif labels is None:
        typer.echo(
            f"note: run {run_dir} has no data file to read labels from ({trained.data_path or 'none recorded'}): "
            "clustered without scores (give --labels)",
            err=True,
        )
    description = f"codes of run {run_dir}: {X.shape[0]} x {X.shape[1]}, numbered by the data file's index{whence}"
    return ClusterPoints(
        X=X, labels=true, label_names=names, path=src, description=description, samples=trained.indices, raw=raw
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


def _write_outputs(tmp: Path, src: Path, result, record: dict, samples=None) -> None:
    """``labels.csv`` (``samples``: each point's index in the data file; default the row),
    ``result.json``, ``clustering.png`` (and the sweep's files) into ``tmp`` (published whole)."""
    from primspace.cluster import clustering_figure, sweep_figure
    from primspace.cluster.outputs import CLUSTER_OUTPUT, write_labels_csv, write_sweep_csv
    from primspace.plots import save_figure
    from primspace.utils.folders import write_json

    n, scores = result.n_samples, result.scores
    shown = "" if result.figure_indices.size == n else f" ({result.figure_indices.size} of {n} samples)"
    acc = "" if scores is None or scores["accuracy"] is None else f", accuracy {scores['accuracy']:.3f}"
    figure = clustering_figure(
        result, title=f"{src.name}: tau = {result.tau:.3g}, R^2 = {result.r2:.4f}, rank {result.rank}{acc}{shown}"
    )
    record["writer"] = CLUSTER_OUTPUT.command  # result.json says who wrote it (primspace.utils.outputs reads it)
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
    if result.selection is not None:
        typer.echo(_format_selection(result.selection))
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


def _primitives_option(k: int | None, deprecated: int | None) -> tuple[int, str]:
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
    if r2 is not None and r2 not in ("auto", "select") and not 0 < r2 < 1:
        raise UserError(f"--r2 must lie in (0, 1), got {r2}")
    if n_init < 1:
        raise UserError(f"--n-init must be at least 1, got {n_init}")


def _parse_r2(text: str | None) -> float | str | None:
    """``--r2``: None, ``"auto"``, ``"select"`` or a number (its range is checked with the other options)."""
    if text is None or text.strip().lower() in ("auto", "select"):
        return None if text is None else text.strip().lower()
    try:
        return float(text)
    except ValueError:
        raise UserError(f"--r2 must be a number in (0, 1), 'auto' or 'select', got {text!r}") from None


def _format_selection(selection: dict) -> str:
    """One line: the chosen target, where it came from, and every candidate's held-out score."""
    candidates = ", ".join(
        f"{c['r2_target']:g} [{'+'.join(c['sources'])}]: " + ("-" if c["score"] is None else f"{c['score']:.3f}")
        for c in selection["candidates"]
    )
    why = f"; {selection['note']}" if selection["note"] else ""
    return (
        f"tau chosen by held-out stability: R^2 target {selection['r2_target']:g} "
        f"({'+'.join(selection['chosen'])}; {candidates}{why})"
    )


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
