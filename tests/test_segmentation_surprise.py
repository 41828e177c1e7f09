"""Boundaries from prediction error (issue 27, item 1): a single-primitive model follows a long
demonstration, and a boundary is where its prediction of the next steps fails."""

from __future__ import annotations

import itertools
import json

import numpy as np

from primspace.data import resample
from primspace.segmentation import boundary_f1
from primspace.segmentation.surprise import (
    HORIZON,
    follow,
    hypotheses,
    segment_by_surprise_templates,
    surprise_threshold,
)
from primspace.segmentation.synthesis import SynthesisSettings
from test_segmentation_synthesis import _chains, _faded, _templates, padded_chains

SETTINGS = SynthesisSettings(18, 36, grid=1)


def test_hypotheses_hold_every_template_at_every_duration():
    templates, _, _ = _templates(per=2)
    hyp = hypotheses(templates, SynthesisSettings(10, 14, grid=2))
    assert hyp.motion.shape == (6 * 3, 14 + HORIZON, 2)
    assert sorted(set(hyp.duration.tolist())) == [10, 12, 14] and set(hyp.template.tolist()) == set(range(6))
    a = int(np.flatnonzero((hyp.template == 4) & (hyp.duration == 12))[0])
    np.testing.assert_allclose(hyp.motion[a, :12], resample([templates[4]], 12)[0])
    assert (hyp.motion[a, 12:] == hyp.motion[a, 11]).all()  # held at its last pose after its end


def test_a_known_primitive_surprises_little_and_its_end_much():
    templates, _, _ = _templates()
    hyp = hypotheses(templates, SETTINGS)
    own = _faded(resample([templates[2]], 27)[0], np.array([0.4, -0.2]))  # a known primitive, started elsewhere
    inside = follow(own, hyp)
    assert np.nanmax(inside[3:]) < 1e-9  # from a few steps on, it predicts its own continuation exactly
    after = np.concatenate([own, _faded(resample([templates[14]], 27)[0], own[-1])])  # then another primitive
    surprise = follow(after, hyp)
    assert np.nanmax(surprise[25:30]) > 1e-3


def test_the_threshold_lies_between_the_surprise_inside_and_at_a_boundary():
    templates, _, _ = _templates()
    threshold = surprise_threshold(templates, SETTINGS)
    assert np.isfinite(threshold) and threshold > 0
    own = resample([templates[7]], 30)[0]
    after = np.concatenate([own, _faded(resample([templates[1]], 30)[0], own[-1])])
    surprise = follow(after, hypotheses(templates, SETTINGS))
    assert np.nanmax(surprise[18:27]) < threshold < np.nanmax(surprise[27:37])


def test_planted_chains_are_cut_where_the_prediction_fails_and_labelled():
    templates, codes, labels = _templates()
    seqs, bounds, steps = _chains(templates, labels)
    padded, lengths = padded_chains(seqs)
    result = segment_by_surprise_templates(padded, lengths, templates, codes, 3, SETTINGS)
    assert boundary_f1(bounds, result.boundaries, 3)["f1"] >= 0.85  # causal: a few found a step or two late
    assert result.chosen["threshold"] > 0 and len(result.penalties) == len(seqs) and (result.penalties >= 0).all()
    for b, n in zip(result.boundaries, lengths):  # every segment within the duration bounds
        edges = np.r_[0, b, n]
        assert (np.diff(edges) >= SETTINGS.min_steps).all()
    found, truth = np.concatenate(result.step_labels), np.concatenate(steps)
    assert max((found == perm[truth]).mean() for perm in map(np.array, itertools.permutations(range(3)))) > 0.9


def test_segment_by_surprise_on_the_command_line(run_cli, tmp_path):
    from primspace.data import MotionDataset
    from test_segmentation_synthesis import single_primitive_run

    pieces = single_primitive_run(run_cli, tmp_path)
    motor, segments = np.zeros((3, 60, 3)), np.full((3, 60), -1)
    for i in range(3):
        motor[i, :30], motor[i, 30:] = pieces.motor[i], pieces.motor[i + 1]
        segments[i] = np.repeat([0, 1], 30)
    MotionDataset(
        motor,
        lengths=[60] * 3,
        step_labels=np.repeat(segments, 1, axis=0),
        step_segments=segments,
        label_names=["a", "b"],
    ).save(tmp_path / "long.h5")
    res = run_cli(
        "segment",
        tmp_path / "run",
        tmp_path / "long.h5",
        "--method",
        "surprise",
        "--min-steps",
        "18",
        "--max-steps",
        "32",
        "--infer-epochs",
        "3",
        "--out",
        tmp_path / "seg",
    )
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "seg" / "result.json").read_text())
    assert result["method"] == "surprise" and len(result["boundaries"]) == 3 and result["scores"]["segments_true"] == 6
    assert result["threshold"] > 0 and result["offset"] in ("fade", "translate")
    assert result["codes"] == "inferred, 3 epochs"


def test_segment_codes_inferred_with_the_weights_frozen(tmp_path):
    """Each found segment gets a code of its own, inferred from its nearest template's code."""
    from primspace.data import MotionDataset
    from primspace.model.config import ModelConfig
    from primspace.segmentation.inferred import in_model_frame
    from primspace.segmentation.synthesis import segment_by_synthesis
    from primspace.train import TrainConfig, fit
    from test_train import primitives

    single = primitives(6, seed=0, T=30, J=3)
    run = fit(
        single,
        model_config=ModelConfig(n_joints=3, length=30, latent_dim=4, layer_sizes=(16, 6)),
        train_config=TrainConfig(epochs=10, seed=0),
        progress=False,
    )
    motor = np.concatenate([single.motor[:3], single.motor[-3:]], axis=1)  # 3 demonstrations of 2 primitives
    segments = np.repeat([[0, 1]], 3, axis=0).repeat(30, axis=1)
    data = MotionDataset(motor, lengths=[60] * 3, step_segments=segments, step_labels=segments, label_names=["a", "b"])
    plain = segment_by_synthesis(run, data, 2, min_steps=20, max_steps=40, offset="fade")
    inferred = segment_by_synthesis(run, data, 2, min_steps=20, max_steps=40, offset="fade", infer_epochs=5)
    assert [b.tolist() for b in inferred.boundaries] == [b.tolist() for b in plain.boundaries]
    assert (
        inferred.chosen["codes"] == "inferred, 5 epochs" and inferred.segment_codes.shape == plain.segment_codes.shape
    )
    assert len(np.unique(inferred.segment_codes.round(9), axis=0)) == len(inferred.segment_codes)  # one code each
    assert not np.allclose(inferred.segment_codes, plain.segment_codes)
    # a template itself, started elsewhere, is moved back onto the template's start
    from primspace.segmentation.synthesis import run_templates

    templates, _ = run_templates(run)
    x = templates[2] + 0.5
    from primspace.segmentation.result import SegmentationResult

    one = SegmentationResult(
        [np.array([])],
        [np.zeros(30, int)],
        np.zeros((1, 4)),
        np.array([0]),
        np.array([0]),
        np.array([30]),
        np.array([0]),
    )
    np.testing.assert_allclose(
        in_model_frame([x], one, templates, np.array([2]), float("inf")), templates[2:3], atol=1e-9
    )
