"""Acting command: act (a scene executed in MuJoCo by the scene policy in closed loop, beside its open
loop and ProMP re-conditioned; docs/act.md)."""

from __future__ import annotations

import re
from pathlib import Path

import typer

from primspace.act.planner import DEFAULT_EVERY
from primspace.cli.app import app
from primspace.cli.options import allow_unfinished_option, check_finished, require_extra, threads_option
from primspace.utils.errors import UserError

#: How the library names the fitted data (``fitted_data=...``): act's flag for it is ``--data``.
_ACT_DATA = re.compile(r"\bfitted_data=(MotionDataset\.load\(PATH\))?")


@app.command("act")
def act_command(
    run: Path = typer.Argument(..., help="A trained run (fit) on simulated demonstrations with camera frames."),
    primitive: str = typer.Option(
        ...,
        "--primitive",
        help="The primitive to do: a label name (push) or its number in the run's list of primitives (not a label id).",
    ),
    scene: str = typer.Option(
        ..., "--scene", help="FILE:INDEX (a data file's sample: its block and first joints) or x,y,size in metres."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="The output directory (executed.h5, act.gif, result.json)."),
    perturb: bool = typer.Option(
        False, "--perturb", help="Move the block by 2-4 cm at 30 % of the motion (seeded by --seed)."
    ),
    every: int = typer.Option(
        DEFAULT_EVERY, "--every", help="Steps between two looks of the closed loop (camera and joints)."
    ),
    seed: int = typer.Option(0, "--seed", help="Seed of the perturbation."),
    data: Path | None = typer.Option(
        None, "--data", help="The run's fitted demonstrations with frames (default: the run's data file)."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUT if it is an earlier act output."),
    threads: int | None = threads_option(),
    allow_unfinished: bool = allow_unfinished_option(),
) -> None:
    """Execute the primitive in the scene in MuJoCo: planned from the camera, re-planned in closed loop when a frame
    surprises the plan; the open loop and ProMP re-conditioned on the executed joints run the same scene."""
    from primspace.act.command import ACT_FILES, ACT_MARK, act, write_outputs
    from primspace.train import TrainConfig, configure_process, load_run
    from primspace.utils.files import check_outside_inputs
    from primspace.utils.folders import OutputKind, atomic_directory
    from primspace.utils.seeds import check_seed

    require_extra("movement_primitives", "movement-primitives", "predict", "act", "ProMP runs the same scene")
    check_seed(seed, "--seed")
    _check_before_work(scene, every)
    inputs = [run] + ([data] if data is not None else []) + ([Path(scene.rpartition(":")[0])] if ":" in scene else [])
    check_outside_inputs(out, inputs)
    configure_process(TrainConfig(threads=threads).validate())
    kind = OutputKind(ACT_MARK, ACT_FILES, frozenset({"writer", "episodes", "scene"}))
    command = {
        "run": str(run),
        "primitive": primitive,
        "scene": scene,
        "perturb": perturb,
        "every": every,
        "seed": seed,
    }
    with atomic_directory(out, overwrite, kind) as tmp:  # checked and locked before minutes of work
        try:
            trained = load_run(run)
            check_finished(trained, allow_unfinished)
            _check_with_run(trained, primitive, scene, data)  # before the frames are read and the policy fitted
            outcome = act(trained, primitive, scene, perturb=perturb, every=every, seed=seed, data=data)
        except UserError as exc:  # the library names fitted_data=, act's flag is --data
            raise UserError(_ACT_DATA.sub("--data PATH", str(exc))) from None
        result = write_outputs(tmp, outcome, command)
    line = ", ".join(f"{name} {'succeeds' if e['success'] else 'fails'}" for name, e in result["episodes"].items())
    lat = result["episodes"]["closed loop"]["latency_ms"]["median"]
    typer.echo(f"wrote {out}: {result['primitive']}: {line}; a plan takes {lat:.2f} ms (median)")


def _check_before_work(scene: str, every: int) -> None:
    """``--every``, and ``--scene``'s form, its block's place or its file's sample, refused in one
    line before the run is read and the policy fitted (the library checks them again, with the run)."""
    from primspace.act.command import read_scene
    from primspace.act.planner import check_every

    check_every(every)
    read_scene(scene)


def _check_with_run(trained, primitive: str, scene: str, data) -> None:
    """``--primitive`` resolved against the labels of the run's fitted demonstrations (as the scene
    policy will), one UserError listing them otherwise; ``--data`` without frames; a ``--scene``
    file's joints against theirs."""
    from primspace.data import MotionDataset
    from primspace.predict.primitives import primitives_from_labels
    from primspace.train.starts import fitted_samples

    fitted = fitted_samples(trained, None if data is None else MotionDataset.load(data))
    if data is not None and not fitted.has_images:
        raise UserError(f"act learns from the fitted demonstrations' camera frames, and {data} has none")
    if fitted.labels is not None:
        primitives_from_labels(fitted.labels, fitted.label_names).resolve(primitive)
    if len(scene.split(",")) != 3:  # FILE:INDEX (its form checked already)
        path, _, index = scene.strip().rpartition(":")
        joints, theirs = MotionDataset.load(path).motor.shape[2], fitted.motor.shape[2]
        if joints != theirs:
            raise UserError(f"--scene {path}: sample {int(index)} has {joints} joints, the run's {theirs}")
