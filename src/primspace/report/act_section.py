"""The report's section of the act experiment (:mod:`primspace.experiments.act`; docs/act.md):
acting from the scene, and in closed loop with the block moved.

Like every section (:mod:`primspace.report.sections`, which imports it from here), it reads
the directory's results files and figures and computes nothing.
"""

from __future__ import annotations

from pathlib import Path

from primspace.report.page import HtmlReport
from primspace.results.act import act_latency_text, act_tables, every_text, move_text
from primspace.results.layout import figures_dir
from primspace.results.readers import read_results

__all__ = ["act", "ACT_SECTION", "act_animations"]

#: The section's heading.
ACT_SECTION = "Acting from the scene and in closed loop"


def _what(results: dict) -> str:
    """The paragraph saying what each table is."""
    move = results.get("perturbation") or {}
    lo, hi = move.get("distance_m", [0.02, 0.04])
    every = every_text(results)
    return (
        "See the block, do the primitive, and keep doing it when the block moves (docs/act.md). Each evaluation "
        f"sample of the intra projection runs at q = {results.get('latent_dim', '?')} (θ frozen) is a scene: its block, "
        "its first joints, its first camera frame and its primitive. "
        "Scene only: a method is given the first frame, the first joints and the primitive (its label), and plans "
        "the whole motion; the motion is judged by the simulator, and its error is the MSE of the steps after the "
        "first (joints scaled to [-1, 1]). The rows: the scene policy (ours: the moments of the block's colour in "
        "the first frame mapped to the motion by a Gaussian process per primitive) and the same map to the run's "
        "codes, decoded (code); the contextual ProMP (ridge from the PCA of the first frame's pixels to the "
        "primitive's ProMP weights; blob: the same from our features); the demonstration with the nearest first "
        "frame, replayed; the mean motion of the primitive; and the reproduction from the whole motion (the run's "
        "inferred codes decoded: the ceiling of anything this run decodes). "
        f"Closed loop: the block is moved by a seeded {100 * lo:g}-{100 * hi:g} cm at {move_text(results)} of the motion "
        "(one draw per sample and seed, the same for every row) and each planner executes step by step in MuJoCo: "
        f"the closed loop (the scene policy asked again {every} with the current frame, its belief "
        "corrected when the frame surprises it), the open loop (its first plan replayed), ProMP re-conditioned on "
        f"the executed joints {every} (it does not see), and the closed loop without the move. "
        "Mean ± sample std (ddof 1) over seeds."
    )


def act_animations(out_dir: Path) -> list[Path]:
    """The act animations an experiment directory holds: ``figures/act*.gif`` and ``figures/animation_act*.gif``."""
    figures = figures_dir(out_dir)
    return sorted(set(figures.glob("act*.gif")) | set(figures.glob("animation_act*.gif")))


def act(out_dir: Path, report: HtmlReport) -> None:
    """Acting from the scene and in closed loop: the three tables, the latency, the animations."""
    results = read_results(out_dir, "act")
    if results is None:
        return
    report.section(ACT_SECTION)
    report.paragraph(_what(results))
    for title, columns, rows in act_tables(results):
        report.table(columns, rows, title)
    report.paragraph(act_latency_text(results))
    if results.get("failures"):
        failures = results["failures"]
        report.note(f"{len(failures)} act point(s) failed: " + "; ".join(failures), "warn")
    for gif in act_animations(out_dir):
        report.figure(gif, "The closed loop's camera beside the open loop's, the joints traced (primspace act).")
