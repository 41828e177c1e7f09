"""See the motion: one animation per primitive, computed from the intra-primitive runs.

For every primitive of the data set, the first evaluation sample of the focus run
(:func:`primspace.experiments.runs.focus_runs`; init ``projection`` when it ran, the
sample that Appendix B's reconstruction figure shows for grasp, push and circle_cw): its
recorded joints and frames, the joints and frames its inferred code generates
(:func:`primspace.train.reconstruct`) and, for simulator data, the simulator replaying the
generated joints (:func:`primspace.sim.render.replay_frames`). The arrays are written as
results (``results/intra_animation.json`` and ``.npz``) and the GIFs drawn from them alone
(:func:`primspace.experiments.figures.draw_animations`:
``figures/animation_<primitive>.gif``), which the report embeds.

:func:`sample_motion` is what ``primspace animate`` computes for one sample.
"""

from __future__ import annotations

import numpy as np

from primspace.experiments import figures
from primspace.experiments.runs import focus_runs
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import ANIMATION_RESULTS, intra_run_dir
from primspace.utils.errors import DataError

__all__ = ["sample_motion", "replay_note", "write_animations"]

# the camera panels of an animation, left to right: array key, label
_PANELS = (("images", "recorded"), ("generated_images", "generated"), ("replay_images", "simulator replay"))

#: Frame size of the replay when the data have no frames to match (H, W).
REPLAY_SIZE = (96, 128)


def replay_note(data, sample: int) -> str | None:
    """None when the simulator can replay ``sample`` of ``data`` (the judge's test:
    :func:`primspace.sim.success.check_judgeable`), else why not, for the title."""
    from primspace.sim.success import check_judgeable

    try:
        check_judgeable(data)
    except DataError:
        return "no simulator replay: not the simulator's data"
    if not 0 <= int(data.labels[sample]) < len(data.label_names):
        return "no simulator replay: the sample has no primitive"
    return None


def sample_motion(run, data, sample: int, *, replay: bool = True, scene=None, device: str = "cpu") -> tuple[dict, dict]:
    """The arrays of one sample's animation and what its title says.

    Parameters
    ----------
    run : TrainedRun
        A run that used ``sample`` (fit or infer).
    data : MotionDataset
        The run's data set (checked by the caller: :func:`primspace.train.check_run_data`).
    sample : int
        Index of the sample in ``data``.
    replay : bool
        Replay the generated joints in the simulator (only for simulator data).
    scene : primspace.sim.scene.Scene, optional
        A scene to reuse across samples.
    device : str
        Where the model decodes (:func:`primspace.train.reconstruct`).

    Returns
    -------
    arrays : dict
        ``motor``, ``generated_motor`` (T, J), and when present ``images``,
        ``generated_images`` and ``replay_images`` (T, H, W, 3) uint8.
    info : dict
        ``sample``, ``primitive``, ``kind``, ``init``, ``latent_dim``, ``joint_names``,
        ``dt``, ``note`` (why there is no replay, or None), ``title`` and ``panels`` (the
        camera panels' labels, left to right).
    """
    from primspace.plots import reconstruction_title
    from primspace.train import reconstruct

    sample = int(sample)
    row = int(np.flatnonzero(run.indices == sample)[0])
    motor, frames = reconstruct(run, run.latents[row : row + 1], device=device)
    truth = data.subset([sample])
    arrays = {"motor": np.asarray(truth.motor[0]), "generated_motor": motor[0]}
    if truth.images is not None:
        arrays["images"] = np.asarray(truth.images)[0]
    if frames is not None:
        arrays["generated_images"] = frames[0]
    label = None if truth.labels is None else int(truth.labels[0])
    primitive = truth.label_names[label] if label is not None and 0 <= label < len(truth.label_names) else None
    note = replay_note(data, sample) if replay else None
    if replay and note is None:
        from primspace.sim.render import replay_frames

        height, width = data.image_size or REPLAY_SIZE
        arrays["replay_images"] = replay_frames(motor[0], truth.params[0], label, height, width, scene=scene)
    title = reconstruction_title(sample, primitive, run.kind, run.init, run.model_config.latent_dim)
    info = {
        "sample": sample,
        "primitive": primitive,
        "kind": run.kind,
        "init": run.init,
        "latent_dim": run.model_config.latent_dim,
        "joint_names": list(truth.joint_names),
        "dt": truth.dt,
        "note": note,
        "title": title + (f" ({note})" if note else ""),
        "panels": [label for key, label in _PANELS if key in arrays],
    }
    return arrays, info


def write_animations(exp: ExperimentDir, results: dict) -> list:
    """Compute every primitive's animation from the focus run (see the module docstring),
    write ``results/intra_animation.json`` / ``.npz``, and draw the GIFs; return their paths."""
    from primspace.plots.animation import FRAME_MS, MAX_FRAMES
    from primspace.train import load_run

    q, seed, inits = focus_runs(exp, results)
    if not inits:
        return []
    with exp.stage("animations"):
        data = exp.dataset()
        init = "projection" if "projection" in inits else inits[0]
        run = load_run(intra_run_dir(exp.path, init, q, seed) / "infer")
        scene = _scene_for(data)
        arrays, animations = {}, []
        for label, name in enumerate(data.label_names):
            members = run.indices[data.labels[run.indices] == label]
            if not members.size:
                continue
            motion, info = sample_motion(run, data, int(members[0]), scene=scene)
            arrays |= {f"{len(animations)}_{key}": value for key, value in motion.items()}
            animations.append(info | {"name": name})
        exp.write_results(ANIMATION_RESULTS, {"animations": animations, "max_frames": MAX_FRAMES, "frame_ms": FRAME_MS})
        exp.write_arrays(ANIMATION_RESULTS, arrays)
        return figures.draw_animations(exp.path)


def _scene_for(data):
    """One simulator scene for every replay (None when the data are not the simulator's)."""
    from primspace.sim.success import check_judgeable

    try:
        check_judgeable(data)
    except DataError:
        return None
    from primspace.sim.scene import Scene

    return Scene()
