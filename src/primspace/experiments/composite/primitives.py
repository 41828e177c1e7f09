"""The composite experiment's segmentation by a model of single primitives: synthesis and surprise.

A sequence of codes (:mod:`primspace.experiments.composite.experiment`) models long demonstrations
but does not find their primitives. A model of *single* primitives does
(docs/sequences.md, issue 27): per seed, one run of the preset's ``primitives`` experiment
preset (its data: the simulator's single primitives, or LASA's single strokes; its
optimiser; q = its ``cluster_latent_dim``; projection init) is fitted on every one of its
single primitives, then segments the seed's held-out long demonstrations two ways:

* **synthesis** (:mod:`primspace.segmentation.synthesis`): the partition whose segments
  the model generates best, by dynamic programming;
* **surprise** (:mod:`primspace.segmentation.surprise`): the model follows each
  demonstration and a boundary is where its prediction of the next steps fails.

Both label the segments by clustering their nearest templates' codes (affine LRSC, τ
without labels), and are scored as the window codes and the peers are: boundary F1 within
the composite preset's window, per-step labelling accuracy.

The single primitives are ``OUT/primitives.h5``, made once (seeded by the experiment's
seed). For LASA only the chained shapes' demonstrations
:data:`~primspace.data.importers.lasa.PRIMITIVE_DEMOS` are fitted, and the chains are made
of the others (:data:`~primspace.data.importers.lasa.CHAIN_DEMOS`): no chained stroke is one
the model has seen. The simulator's single primitives and its long demonstrations are
drawn separately (other block placements, other seeds' streams).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.composite.timeline import TIMELINE_SAMPLES, padded_boundaries
from primspace.experiments.presets import LASA_DATA, ExperimentPreset, resolve_preset
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.results.composite import METHODS
from primspace.utils.errors import UserError

__all__ = [
    "PRIMITIVES_FILE",
    "METHODS",
    "TIMELINE_FILE",
    "primitives_key",
    "primitive_indices",
    "run_primitives_point",
    "run_primitives",
]

#: The single primitives' data file inside the experiment folder.
PRIMITIVES_FILE = "primitives.h5"
#: A point's arrays for the report's timeline figures (inside ``OUT/runs/<key>/``; the first
#: seed's are copied to ``OUT/results/composite_primitives.npz``, which the figures read).
TIMELINE_FILE = "timeline.npz"


def primitives_key(seed: int) -> str:
    """The grid key (and ``OUT/runs/`` folder) of one seed's model of single primitives."""
    return f"composite/primitives-s{seed}"


def primitive_indices(data: MotionDataset, preset: ExperimentPreset) -> np.ndarray:
    """The samples of the single primitives that are fitted: all of them, or for LASA the
    chained shapes' :data:`~primspace.data.importers.lasa.PRIMITIVE_DEMOS`."""
    if preset.data_preset != LASA_DATA:
        return np.arange(len(data))
    from primspace.data.importers.lasa import CHAIN_SHAPES, PRIMITIVE_DEMOS

    keep = []
    for i, (label, source) in enumerate(zip(data.labels, [] if data.source_ids is None else data.source_ids)):
        demo = int(str(source).rsplit(" ", 1)[-1])
        if data.label_names[int(label)] in CHAIN_SHAPES and demo in PRIMITIVE_DEMOS:
            keep.append(i)
    return np.asarray(keep, dtype=np.int64)


def template_label_bound(fitted, primitives: MotionDataset, held: MotionDataset, result) -> float | None:
    """Per-step labelling accuracy when each found segment takes the *true* primitive of its
    nearest template (the single primitives' labels): the most that any clustering of the
    segments' template codes can reach with these segments. None without labels."""
    from primspace.segmentation import step_labelling_accuracy

    if primitives.labels is None or (primitives.labels < 0).any():
        return None
    names = list(held.label_names)
    labels = np.array(
        [
            names.index(primitives.label_names[int(v)]) if primitives.label_names[int(v)] in names else -1
            for v in primitives.labels[np.asarray(fitted.indices)]
        ]
    )
    found = np.full(held.step_labels.shape, -1)
    for i, a, b, t in zip(result.segment_sample, result.segment_start, result.segment_stop, result.segment_templates):
        found[i, a:b] = labels[t]
    return step_labelling_accuracy(held.step_labels, found)


def run_primitives_point(
    run_dir: Path, primitives_path: str, indices: list, data_path: str, eval_idx: list, preset: dict, seed: int
) -> dict:
    """One seed: fit the model of single primitives, then segment the held-out long
    demonstrations by synthesis and by surprise and score both."""
    from primspace.experiments.runs import experiment_scaler, shared_fit, train_configs
    from primspace.segmentation import segmentation_scores
    from primspace.segmentation.surprise import segment_by_surprise
    from primspace.segmentation.synthesis import segment_by_synthesis
    from primspace.sim.composite import transition_steps
    from primspace.train import configure_process

    composite = ExperimentPreset.from_dict(preset)
    single = resolve_preset(composite.primitives)
    primitives = MotionDataset.load(primitives_path)
    q = single.cluster_latent_dim
    model_config, train_config = train_configs(single, q, seed, single.fit_epochs)
    configure_process(train_config)
    start = time.perf_counter()
    fitted = shared_fit(
        run_dir / "fit",
        dataset=primitives,
        model_config=model_config,
        train_config=train_config,
        init="projection",
        indices=np.asarray(indices),
        images=False,
        scaler=experiment_scaler(primitives),
        progress=False,
    )
    out = {
        "seed": seed,
        "preset": single.name,
        "latent_dim": q,
        "n_templates": len(indices),
        "fit_seconds": round(time.perf_counter() - start, 2),
        "final_loss": fitted.history[-1]["loss"],
    }
    held = MotionDataset.load(data_path).subset(np.asarray(eval_idx))
    k = max(len(held.label_names), 1)
    lo, hi = composite.segment_steps or (None, None)
    window = composite.model.code_window
    timeline = {}
    for name, method in zip(METHODS, (segment_by_synthesis, segment_by_surprise)):
        start = time.perf_counter()
        result = method(fitted, held, k, min_steps=lo, max_steps=hi, random_state=seed)
        timeline |= _timeline_arrays(name, fitted, held, result)
        scores = segmentation_scores(result, held, window, transition_steps(held))
        out[name] = scores | {
            "seconds": round(time.perf_counter() - start, 2),
            "note": result.note,
            "accuracy_template_labels": template_label_bound(fitted, primitives, held, result),
        }
        out[name] |= {k: result.chosen[k] for k in ("offset", "costs", "threshold") if k in result.chosen}
    from primspace.utils.files import atomic_path

    with atomic_path(run_dir / TIMELINE_FILE) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **timeline)
    return out


def _timeline_arrays(name: str, fitted, held: MotionDataset, result) -> dict:
    """The first :data:`~primspace.experiments.composite.timeline.TIMELINE_SAMPLES` held-out
    demonstrations' scaled joints, true steps and ``name``'s found labels and boundaries."""
    n = min(TIMELINE_SAMPLES, len(held))
    return {
        "joints": fitted.scaler.transform(np.asarray(held.motor[:n], dtype=np.float64)),
        "lengths": held.lengths[:n],
        "step_labels": held.step_labels[:n],
        "step_segments": held.step_segments[:n],
        f"found_{name}": result.padded_step_labels(held.length)[:n],
        f"bounds_{name}": padded_boundaries(result.boundaries[:n]),
    }


def _check_unseen(chains: MotionDataset) -> None:
    """Refuse LASA chains that use a demonstration the model of single strokes is fitted on
    (chains made before 0.8 drew from all seven)."""
    from primspace.data.importers.lasa import PRIMITIVE_DEMOS

    for i, source in enumerate([] if chains.source_ids is None else chains.source_ids):
        pieces = str(source).split(": ", 1)[-1].split(" + ")
        if any(int(p.rsplit(" ", 1)[-1]) in PRIMITIVE_DEMOS for p in pieces if " demo " in p):
            raise UserError(
                f"{chains.source or 'the data'}: chain {i} ({source}) uses a LASA demonstration "
                f"({', '.join(map(str, PRIMITIVE_DEMOS))}) that the model of single strokes is fitted on; "
                "chains made before 0.8 drew from all seven: run the experiment into a new --out"
            )


def run_primitives(exp: ExperimentDir, splits: dict) -> list[dict]:
    """Every seed's point (``splits``: seed -> held-out indices of the long demonstrations);
    the finished ones' results, in seed order. Nothing when the preset names no
    ``primitives``."""
    if exp.preset.primitives is None:
        return []
    single = resolve_preset(exp.preset.primitives)
    if single.data_preset == LASA_DATA:
        _check_unseen(exp.dataset())
    path = exp.path / PRIMITIVES_FILE
    if not path.exists():
        exp.write_data(single.data_preset, path, single.lasa_length, stage="single primitives data")
    indices = primitive_indices(MotionDataset.load(path), single).tolist()
    points = [
        GridPoint(
            primitives_key(seed), (str(path), indices, str(exp.data_path), splits[seed], exp.preset.to_dict(), seed)
        )
        for seed in exp.preset.seeds
    ]
    with exp.stage("composite primitives"):
        grid = exp.grid(run_primitives_point, points, "single-primitive segmentation")
    done = [grid.results[p.key] for p in points if p.key in grid.results]
    if done:  # the first finished seed's timeline, where the figures read it
        from primspace.results.layout import run_dir_of

        with np.load(run_dir_of(exp.path, primitives_key(done[0]["seed"])) / TIMELINE_FILE) as npz:
            exp.write_arrays("composite_primitives", {k: npz[k] for k in npz.files})
    return done
