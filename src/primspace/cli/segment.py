"""The ``segment`` command: the primitives in long demonstrations, found by a run."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import configure_threads, threads_option
from primspace.utils.errors import UserError

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
    method: SegmentMethod | None = _SEGMENT_METHOD,
    primitives: int | None = typer.Option(
        None, "--primitives", "-k", help="Number of primitives K (default: the data's label names)."
    ),
    tolerance: int | None = typer.Option(
        None,
        "--tolerance",
        help="Steps within which a found boundary matches a true one (default: the code window; surprise, synthesis: 8).",
    ),
    min_steps: int | None = typer.Option(None, "--min-steps", help=_STEPS.format("fewest", "0.4")),
    max_steps: int | None = typer.Option(None, "--max-steps", help=_STEPS.format("most", "0.85")),
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
    threads: int | None = threads_option(),
) -> None:
    """Find the primitives in long demonstrations: boundaries (change points of a run's window
    codes, or the segments a single-primitive run generates best) and labels (affine subspace
    clustering of segment codes); scored against the data's step_segments / step_labels when it has them."""
    import numpy as np

    from primspace.data import MotionDataset
    from primspace.train import load_run
    from primspace.utils.files import check_outside_inputs
    from primspace.utils.folders import OutputKind, atomic_directory, check_output_directory, write_json

    kind = OutputKind("primspace segment", SEGMENT_FILES, frozenset({"window", "boundaries", "scores"}))
    check_outside_inputs(out, (run, data))
    check_output_directory(out, overwrite, kind)
    configure_threads(threads)
    with atomic_directory(out, overwrite, kind) as tmp:  # checked and locked before any work
        trained = load_run(run)
        method = segment_method(method, trained)
        _check_segment_options(method, min_steps, max_steps, offset, infer_epochs, tolerance)
        ds = MotionDataset.load(data)
        segment = _segment_windows if method is SegmentMethod.windows else _segment_by_primitives
        amounts = (min_steps, max_steps, offset.value, infer_epochs)
        samples, held, result, scores, window, k = segment(
            trained, ds, run, data, primitives, tolerance, amounts, method.value
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
        _write_segments(tmp / "segments.csv", samples, result)
        np.save(tmp / "step_labels.npy", result.padded_step_labels(held.length))
        _timeline(tmp / "timeline.png", trained, held, result, window, method.value)
        write_json(tmp / "result.json", record | {"writer": kind.command})
    typer.echo(_segment_summary(scores, len(held)))
    typer.echo(f"wrote {out}")


def segment_method(method: SegmentMethod | None, trained) -> SegmentMethod:
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


def _primitives(held, primitives: int | None, data: Path) -> int:
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
    from primspace.utils.progress import stage

    k = _primitives(ds, primitives, data)
    segment = segment_by_surprise if method == "surprise" else segment_by_synthesis
    with stage(f"segment: {len(ds)} demonstrations by {method}"):
        result = segment(trained, ds, k, min_steps=steps[0], max_steps=steps[1], offset=steps[2], infer_epochs=steps[3])
    scores = segmentation_scores(result, ds, 8 if tolerance is None else tolerance, transition_steps(ds))
    return np.arange(len(ds)), ds, result, scores, 1, k


def _write_segments(path: Path, samples, result) -> None:
    """One row per segment: the sample (data index), its segment number, steps, label."""
    from collections import Counter

    from primspace.utils.files import atomic_write_text

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
