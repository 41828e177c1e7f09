"""Boundaries by synthesis (issue 27, item 2): the partition into segments that single-primitive
templates explain best, and the segments labelled by clustering their templates' codes."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset, resample
from primspace.segmentation import boundary_f1
from primspace.segmentation.synthesis import (
    SynthesisSettings,
    best_partition,
    candidate_costs,
    candidate_segments,
    segment_by_templates,
)
from test_train import primitives


def _templates(t1=30, per=6, seed=0):
    """Three primitive families in 2-D (a reach, a circle, a zigzag), ``per`` variants each, and their codes."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, t1)
    shapes, codes = [], []
    for k in range(3):
        for _ in range(per):
            a = rng.uniform(0.8, 1.2)
            if k == 0:
                y = np.c_[a * t, 0.3 * a * t**2]
            elif k == 1:
                y = 0.5 * a * np.c_[np.cos(2 * np.pi * t) - 1, np.sin(2 * np.pi * t)]
            else:
                y = np.c_[0.6 * a * np.abs(np.sin(3 * np.pi * t)), -0.8 * a * t]
            shapes.append(y)
            code = np.zeros(6)
            code[2 * k : 2 * k + 2] = [1.0, a - 1.0]  # one 2-D affine subspace per primitive
            codes.append(code + rng.normal(0, 1e-3, 6))
    return np.stack(shapes), np.stack(codes), np.repeat(np.arange(3), per)


def _faded(piece, start, fade=0.35):
    """``piece`` started at ``start``: the offset fades out over the first ``fade`` of its steps
    (a primitive begun where the last one ended, then on its own path: the case the cost models)."""
    ramp = np.clip(1.0 - np.arange(len(piece)) / (fade * len(piece)), 0.0, 1.0)[:, None]
    return piece + ramp * (start - piece[0])


def _chains(templates, labels, n=8, seed=1):
    """Long demonstrations: 2-3 templates each stretched to 20-34 steps, each piece starting where the last ended."""
    rng = np.random.default_rng(seed)
    seqs, bounds, steps = [], [], []
    for _ in range(n):
        pieces, owners, start = [], [], np.zeros(2)
        for k in rng.choice(len(templates), int(rng.integers(2, 4)), replace=False):
            piece = resample([templates[k]], int(rng.integers(20, 35)))[0]
            pieces.append(_faded(piece, start))
            owners.append(labels[k])
            start = pieces[-1][-1]
        seqs.append(np.concatenate(pieces))
        bounds.append(np.cumsum([len(p) for p in pieces])[:-1])
        steps.append(np.repeat(owners, [len(p) for p in pieces]))
    return seqs, bounds, steps


def padded_chains(chains):
    """Ragged ``(L_i, 2)`` chains as one zero-padded ``(N, T, 2)`` array, and their lengths."""
    lengths = np.array([len(c) for c in chains])
    padded = np.zeros((len(chains), lengths.max(), 2))
    for i, c in enumerate(chains):
        padded[i, : len(c)] = c
    return padded, lengths


def test_candidates_tile_and_the_last_ends_at_the_length():
    keys = candidate_segments(61, SynthesisSettings(20, 30, grid=3))
    assert (keys[:, 0] % 3 == 0).all() and ((keys[:, 1] - keys[:, 0]) >= 20).all()
    assert ((keys[:, 1] - keys[:, 0]) <= 30).all() and (keys[:, 1] <= 61).all()
    assert (61 in keys[:, 1]) and not ((keys[:, 1] > 41) & (keys[:, 1] < 61)).any()  # no stub shorter than 20 left


def test_the_partition_is_the_least_cost_tiling():
    rng = np.random.default_rng(3)
    settings = SynthesisSettings(3, 6, grid=1)
    keys = candidate_segments(14, settings)
    cost = rng.uniform(0, 1, len(keys))
    chosen = best_partition(14, keys, cost)
    total = sum(cost[k] * (keys[k, 1] - keys[k, 0]) for k in chosen)
    assert keys[chosen[0], 0] == 0 and keys[chosen[-1], 1] == 14
    assert all(keys[a, 1] == keys[b, 0] for a, b in zip(chosen, chosen[1:]))
    index = {tuple(k): i for i, k in enumerate(keys)}
    best = np.inf
    for cuts in itertools.chain.from_iterable(itertools.combinations(range(3, 12), r) for r in range(0, 4)):
        edges = (0, *cuts, 14)
        parts = [index.get((a, b)) for a, b in zip(edges, edges[1:])]
        if None not in parts:
            best = min(best, sum(cost[p] * (keys[p, 1] - keys[p, 0]) for p in parts))
    assert total == pytest.approx(best)
    assert best_partition(14, keys[keys[:, 1] < 14], cost[keys[:, 1] < 14]) == []  # nothing reaches the end


def test_a_start_offset_is_faded_out():
    templates, _, _ = _templates()
    x = _faded(templates[4], templates[4][0] + np.array([0.7, -0.4]))  # the template, started elsewhere
    keys = np.array([[0, 30]])
    faded, near = candidate_costs(x, keys, templates, fade=0.35)
    assert near[0] == 4 and faded[0] < 1e-12
    # only the start is forgiven: an offset that persists costs
    persistent, _ = candidate_costs(templates[4] + np.array([0.7, -0.4]), keys, templates, fade=0.35)
    assert persistent[0] > 0.01


def test_planted_chains_are_segmented_and_labelled():
    templates, codes, labels = _templates()
    seqs, bounds, steps = _chains(templates, labels)
    padded, lengths = padded_chains(seqs)
    result = segment_by_templates(padded, lengths, templates, codes, 3, SynthesisSettings(18, 36, grid=1))
    assert boundary_f1(bounds, result.boundaries, 2)["f1"] == 1.0
    found = np.concatenate(result.step_labels)
    truth = np.concatenate(steps)
    assert max((found == perm[truth]).mean() for perm in map(np.array, itertools.permutations(range(3)))) > 0.97


def single_primitive_run(run_cli, tmp_path):
    """A run of single primitives trained by the command line (``tmp_path/run``), and 4 other primitives."""
    primitives(6, seed=0, T=30, J=3).save(tmp_path / "single.h5")
    assert (
        run_cli(
            "train",
            tmp_path / "single.h5",
            "--epochs",
            "10",
            "--latent-dim",
            "4",
            "--layers",
            "16,6",
            "--out",
            tmp_path / "run",
        ).code
        == 0
    )
    return primitives(4, seed=1, T=30, J=3)


@pytest.mark.slow
def test_segment_by_synthesis_on_the_command_line(run_cli, tmp_path):
    pieces = single_primitive_run(run_cli, tmp_path)
    rng = np.random.default_rng(0)
    motor, segments, step_labels, lengths = np.zeros((4, 90, 3)), np.full((4, 90), -1), np.full((4, 90), -1), []
    for i in range(4):
        chosen = rng.choice(len(pieces), 3, replace=False)
        parts = [resample([pieces.motor[k]], int(rng.integers(20, 31)))[0] for k in chosen]
        n = sum(len(p) for p in parts)
        motor[i, :n], motor[i, n:] = np.concatenate(parts), parts[-1][-1]
        segments[i, :n] = np.repeat(np.arange(3), [len(p) for p in parts])
        step_labels[i, :n] = np.repeat(pieces.labels[chosen], [len(p) for p in parts])
        lengths.append(n)
    MotionDataset(
        motor, lengths=lengths, step_labels=step_labels, step_segments=segments, label_names=["a", "b", "c"]
    ).save(tmp_path / "long.h5")
    res = run_cli(
        "segment",
        tmp_path / "run",
        tmp_path / "long.h5",
        "--method",
        "synthesis",
        "--min-steps",
        "18",
        "--max-steps",
        "32",
        "--out",
        tmp_path / "seg",
    )
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "seg" / "result.json").read_text())
    assert result["method"] == "synthesis" and result["n_primitives"] == 3 and len(result["boundaries"]) == 4
    assert 0 <= result["scores"]["boundary"]["f1"] <= 1 and result["scores"]["segments_true"] == 12
    assert np.load(tmp_path / "seg" / "step_labels.npy").shape == (4, 90)
    windows = ("--method", "windows")  # a single-primitive run is segmented by synthesis unless told otherwise
    assert_user_error(
        run_cli(
            "segment", tmp_path / "run", tmp_path / "long.h5", *windows, "--min-steps", "5", "--out", tmp_path / "s2"
        ),
        "--min-steps, --max-steps, --offset and --infer-epochs apply",
    )
    assert_user_error(
        run_cli("segment", tmp_path / "run", tmp_path / "long.h5", *windows, "--out", tmp_path / "s3"),
        "--method windows needs a run trained with --code-window",
    )


def test_a_demonstration_that_no_tiling_fits_is_one_segment_of_its_nearest_template():
    templates, codes, labels = _templates()
    x = resample([templates[7]], 45)[0]  # segments of 25..36 steps cannot tile 45 (one is too short, two too long)
    result = segment_by_templates(x[None], [45], templates, codes, 3, SynthesisSettings(25, 36, grid=1))
    assert result.boundaries[0].size == 0
    assert result.segment_start.tolist() == [0] and result.segment_stop.tolist() == [45]
    assert np.allclose(result.segment_codes[0], codes[7]) and result.penalties[0] < 1e-3


@pytest.mark.slow
def test_the_offset_model_is_chosen_by_how_well_it_explains_the_data():
    from primspace.segmentation.synthesis import OFFSETS, by_offset

    templates, codes, labels = _templates()
    seqs, bounds, _ = _chains(templates, labels)  # each piece's start offset faded out
    rng = np.random.default_rng(4)
    shifted = []  # the same pieces translated whole to start where the last ended (chained LASA strokes)
    for s, b in zip(seqs, bounds):
        pieces = np.split(s, b)
        out, start = [], np.zeros(2)
        for p in pieces:
            raw = templates[rng.integers(len(templates))]
            piece = resample([raw], len(p))[0]
            out.append(piece - piece[0] + start)
            start = out[-1][-1]
        shifted.append(np.concatenate(out))

    def run(chains, offset):
        padded, lengths = padded_chains(chains)
        settings = lambda fade: SynthesisSettings(18, 36, grid=1, fade=fade)  # noqa: E731
        return by_offset(
            lambda fade: segment_by_templates(padded, lengths, templates, codes, 3, settings(fade)), offset
        )

    faded, translated = run(seqs, "auto"), run(shifted, "auto")
    assert faded.chosen["offset"] == "fade" and translated.chosen["offset"] == "translate"
    assert translated.chosen["costs"]["translate"] < translated.chosen["costs"]["fade"]
    assert boundary_f1(bounds, translated.boundaries, 2)["f1"] == 1.0
    assert run(shifted, "fade").chosen == {"offset": "fade"} and set(OFFSETS) == {"fade", "translate"}


def test_max_steps_beyond_the_data_are_capped_at_its_length(run_cli, tmp_path):
    """Issue 38, item 5: --max-steps 1e20 never returned (synthesis) and 5000 on 40-step data took
    gigabytes (surprise): no segment can outlast the data, so the duration is capped at its T."""
    from primspace.segmentation.surprise import segment_by_surprise
    from primspace.segmentation.synthesis import model_inputs, segment_by_synthesis
    from primspace.train import load_run

    pieces = single_primitive_run(run_cli, tmp_path)
    run = load_run(tmp_path / "run")
    long = MotionDataset(
        np.concatenate([pieces.motor[:2], pieces.motor[2:4]], axis=1)[:, :40], joint_names=pieces.joint_names
    )
    assert model_inputs(run, long, min_steps=8, max_steps=10**20)[-1].max_steps == 40
    capped = segment_by_synthesis(run, long, 3, min_steps=8, max_steps=10**20)
    same = segment_by_synthesis(run, long, 3, min_steps=8, max_steps=40)
    assert [list(b) for b in capped.boundaries] == [list(b) for b in same.boundaries]
    assert len(segment_by_surprise(run, long, 3, min_steps=8, max_steps=5000).boundaries) == 2
