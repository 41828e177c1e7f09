"""The experiments' figures, drawn from their results files alone.

Each function reads ``OUT/results`` (JSON and arrays, :mod:`primspace.results.readers`)
and writes PNGs (and the animations' GIFs) to ``OUT/figures``; none loads a model or the data set, so a figure can be
redrawn from a finished experiment directory. The experiments call them when they end.
Imports no experiment.
"""

from __future__ import annotations

from pathlib import Path

from primspace.results.layout import ANIMATION_RESULTS, IMAGE_STRIPS, LATENT_RESULTS, animation_file, figure_file
from primspace.results.readers import read_arrays, read_results

__all__ = ["draw_intra", "draw_latent", "draw_animations", "draw_inter", "draw_latent_accuracy", "draw_composite"]


def draw_intra(out_dir: str | Path) -> list[Path]:
    """The paper's two convergence figures (fit, infer), then :func:`draw_latent`."""
    from primspace import plots

    results = read_results(out_dir, "intra")
    if results is None or not results["runs"]:
        return []
    drawn = []
    for phase, title in (("fit", "fit θ and Z (train part)"), ("infer", "infer Z, θ frozen (eval part)")):
        fig = plots.plot_intra_losses(results["runs"], phase=phase, title=f"Intra-primitive: {title}")
        drawn.append(plots.save_figure(fig, figure_file(out_dir, f"intra_loss_{phase}")))
    return drawn + draw_latent(out_dir)


def draw_latent(out_dir: str | Path) -> list[Path]:
    """The latent-encoding figure (2-D and 3-D principal components of one primitive's
    codes per init) and the Appendix B reconstructions, from ``intra_latent``."""
    from primspace import plots

    meta, arrays = read_results(out_dir, LATENT_RESULTS), read_arrays(out_dir, LATENT_RESULTS)
    if meta is None or arrays is None:
        return []
    drawn = []
    primitive = int(meta["primitive"])
    if "params" in arrays:
        codes = {init: arrays[f"codes_{init}"] for init in meta["inits"]}
        for dims in (2, 3):
            fig = plots.plot_latent_pca(
                codes,
                arrays["labels"],
                arrays["params"],
                primitive=primitive,
                primitive_name=meta["label_names"][primitive],
                n_components=dims,
            )
            drawn.append(plots.save_figure(fig, figure_file(out_dir, f"latent_pca{dims}d")))
    for r in meta["reconstructions"]:
        prefix = f"recon_{r['name']}_"
        fig = plots.plot_reconstruction(
            arrays[prefix + "motor"],
            arrays[prefix + "generated_motor"],
            images=arrays.get(prefix + "images"),
            generated_images=arrays.get(prefix + "generated_images"),
            generated_keypoints=arrays.get(prefix + "generated_keypoints"),
            joint_names=r["joint_names"],
            dt=r["dt"],
            title=plots.reconstruction_title(r["sample"], r["primitive"], r["kind"], r["init"], r["latent_dim"]),
        )
        drawn.append(plots.save_figure(fig, figure_file(out_dir, f"reconstruction_{r['name']}")))
    return drawn


def draw_animations(out_dir: str | Path) -> list[Path]:
    """One GIF per primitive (:func:`primspace.plots.draw_animation`, at most the results'
    ``max_frames`` frames) from ``intra_animation``: recorded, generated and replayed frames
    beside the joint trace; and, when the frames were generated, one still figure of
    generated against recorded frames of every primitive (``figures/image_strips.png``)."""
    from primspace import plots

    meta, arrays = read_results(out_dir, ANIMATION_RESULTS), read_arrays(out_dir, ANIMATION_RESULTS)
    if meta is None or arrays is None:
        return []
    drawn = []
    for k, a in enumerate(meta["animations"]):
        motion = {key: arrays.get(f"{k}_{key}") for key in ("images", "generated_images", "replay_images")}
        drawn.append(
            plots.draw_animation(
                animation_file(out_dir, a["name"]),
                arrays[f"{k}_motor"],
                arrays[f"{k}_generated_motor"],
                **motion,
                joint_names=a["joint_names"],
                dt=a["dt"],
                title=a["title"],
                max_frames=meta["max_frames"],
                frame_ms=meta["frame_ms"],
            )
        )
    strips = [
        (a["name"], arrays[f"{k}_images"], arrays[f"{k}_generated_images"])
        for k, a in enumerate(meta["animations"])
        if f"{k}_images" in arrays and f"{k}_generated_images" in arrays
    ]
    if strips:
        a = meta["animations"][0]
        fig = plots.plot_image_strips(
            strips,
            title=f"Generated against recorded frames, one evaluation sample per primitive "
            f"({a['kind']} run, init {a['init']}, q={a['latent_dim']})",
        )
        drawn.append(plots.save_figure(fig, figure_file(out_dir, IMAGE_STRIPS)))
    return drawn


def draw_inter(out_dir: str | Path) -> list[Path]:
    """The paper's inter-primitive figure: phase-2 loss, mean ± std over folds, per init."""
    from primspace import plots

    results = read_results(out_dir, "inter")
    if results is None or not results["runs"]:
        return []
    histories: dict[str, list] = {}
    for r in results["runs"]:
        histories.setdefault(r["init"], []).append(r["phase2"])
    fig = plots.plot_loss_curves(
        histories,
        title=f"Inter-primitive, phase 2 (new primitive + {results['replay']:.0%} replay), "
        f"q = {results['latent_dim']}: mean ± std over folds",
    )
    return [plots.save_figure(fig, figure_file(out_dir, "inter_loss"))]


def draw_latent_accuracy(out_dir: str | Path) -> list[Path]:
    """Clustering accuracy of the codes against the R² target that picks τ."""
    from primspace import plots

    results = read_results(out_dir, "clustering")
    if results is None or not results.get("latent_sweep"):
        return []
    fig = plots.plot_accuracy_vs_r2(
        results["latent_sweep"], title=f"Clustering the codes (q = {results['latent_dim']}): accuracy per R² target"
    )
    return [plots.save_figure(fig, figure_file(out_dir, "latent_accuracy_vs_r2"))]


def draw_composite(out_dir: str | Path) -> list[Path]:
    """Long demonstrations: the fit and inference losses per init, and per init the
    timeline of a few held-out demonstrations' codes with true and found boundaries."""
    from primspace import plots
    from primspace.plots.sequences import plot_code_timeline
    from primspace.segmentation import boundaries_from_segments

    results = read_results(out_dir, "composite")
    if results is None or not results["runs"]:
        return []
    drawn = []
    for phase, title in (("fit", "fit θ and the code sequences"), ("infer", "infer the code sequences, θ frozen")):
        fig = plots.plot_intra_losses(results["runs"], phase=phase, title=f"Long demonstrations: {title}")
        drawn.append(plots.save_figure(fig, figure_file(out_dir, f"composite_loss_{phase}")))
    meta, arrays = read_results(out_dir, "composite_timeline"), read_arrays(out_dir, "composite")
    if meta is None or arrays is None:
        return drawn
    true_bounds = boundaries_from_segments(arrays["step_segments"], arrays["lengths"])
    for init in meta["inits"]:
        found = [b[b >= 0] for b in arrays[f"bounds_{init}"]]
        fig = plot_code_timeline(
            arrays[f"codes_{init}"],
            meta["window"],
            arrays["lengths"],
            arrays["step_labels"],
            arrays[f"found_{init}"],
            true_bounds,
            found,
            label_names=meta["label_names"],
            title=f"{init}: inferred code sequences (q = {meta['latent_dim']}, W = {meta['window']}), held-out demonstrations",
        )
        drawn.append(plots.save_figure(fig, figure_file(out_dir, f"composite_timeline_{init}")))
    return drawn + _draw_primitive_timelines(out_dir, results)


def _draw_primitive_timelines(out_dir: str | Path, results: dict) -> list[Path]:
    """Per method of the model of single primitives, the timeline of the first seed's
    held-out demonstrations: scaled joints, true and found labels and boundaries."""
    from primspace import plots
    from primspace.plots.sequences import plot_code_timeline
    from primspace.results.composite import METHODS
    from primspace.segmentation import boundaries_from_segments

    arrays, rows = read_arrays(out_dir, "composite_primitives"), results.get("primitives") or []
    if arrays is None or not rows:
        return []
    true_bounds = boundaries_from_segments(arrays["step_segments"], arrays["lengths"])
    drawn = []
    for name in (m for m in METHODS if f"found_{m}" in arrays):
        fig = plot_code_timeline(
            arrays["joints"],
            1,
            arrays["lengths"],
            arrays["step_labels"],
            arrays[f"found_{name}"],
            true_bounds,
            [b[b >= 0] for b in arrays[f"bounds_{name}"]],
            label_names=results.get("label_names") or (),
            title=f"{name} ({rows[0]['preset']} single primitives, seed {rows[0]['seed']}): "
            "scaled joints of held-out demonstrations",
        )
        drawn.append(plots.save_figure(fig, figure_file(out_dir, f"composite_timeline_{name}")))
    return drawn
