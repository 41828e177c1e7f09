"""The step fields (lengths, step_labels, step_segments) of demonstrations of different
lengths made of several primitives: kept through a file, subset, and every bad value
refused with the field, sample and step named."""

import numpy as np
import pytest

from primspace.data import DatasetWriter, MotionDataset
from primspace.utils.errors import DataError

MOTOR = np.random.default_rng(0).normal(size=(3, 6, 2))
LENGTHS = np.array([6, 4, 3])
LABELS = np.array([[0, 0, 1, 1, 2, 2], [1, 1, 0, 0, -1, -1], [2, 2, 2, -1, -1, -1]])
SEGMENTS = np.array([[0, 0, 1, 1, 2, 2], [0, 0, 1, 1, -1, -1], [0, 0, 0, -1, -1, -1]])


def _ds(**kw):
    args = dict(
        labels=[-1, -1, -1], label_names=["a", "b", "c"], lengths=LENGTHS, step_labels=LABELS, step_segments=SEGMENTS
    )
    return MotionDataset(MOTOR, **{**args, **kw})


def test_step_fields_survive_a_file_and_a_subset(tmp_path):
    back = MotionDataset.load(_ds().save(tmp_path / "d.h5"))
    np.testing.assert_array_equal(back.lengths, LENGTHS)
    np.testing.assert_array_equal(back.step_segments, SEGMENTS)
    sub = back.subset([2, 0])
    np.testing.assert_array_equal(sub.lengths, [3, 6])
    np.testing.assert_array_equal(sub.step_labels, LABELS[[2, 0]])


def test_the_writer_writes_step_fields_in_blocks(tmp_path):
    with DatasetWriter(
        tmp_path / "w.h5",
        n_samples=3,
        length=6,
        joint_names=["x", "y"],
        label_names=["a", "b", "c"],
        with_labels=True,
        with_steps=True,
    ) as w:
        for i in range(3):
            w.write(
                i,
                motor=MOTOR[i : i + 1],
                labels=[-1],
                lengths=LENGTHS[i : i + 1],
                step_labels=LABELS[i : i + 1],
                step_segments=SEGMENTS[i : i + 1],
            )
    np.testing.assert_array_equal(MotionDataset.load(tmp_path / "w.h5").step_labels, LABELS)
    with pytest.raises(DataError, match="missing from a block"):
        with DatasetWriter(tmp_path / "x.h5", n_samples=1, length=6, joint_names=["x", "y"], with_steps=True) as w:
            w.write(0, motor=MOTOR[:1])
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(step_labels=None, step_segments=None), "field 'lengths': given without step_labels, step_segments"),
        (dict(lengths=None), "field 'step_labels': given without lengths"),
        (dict(lengths=np.array([6, 4, 7])), "field 'lengths', sample 2: length 7 out of range \\[2, T=6\\]"),
        (dict(lengths=np.array([6, 1, 3])), "field 'lengths', sample 1: length 1 out of range"),
        (
            dict(step_labels=np.where(LABELS == -1, 0, LABELS)),
            "field 'step_labels', sample 1: step 4: -1 must mark exactly",
        ),
        (
            dict(step_labels=np.where(LABELS == 2, 3, LABELS)),
            "field 'step_labels', sample 0: label 3 out of range \\[0, 2\\]",
        ),
        (
            dict(step_segments=np.where(SEGMENTS == 1, 3, SEGMENTS)),
            "field 'step_segments', sample 0: segment indices must start at 0",
        ),
        (
            dict(step_segments=SEGMENTS + (SEGMENTS >= 0)),
            "field 'step_segments', sample 0: segment indices must start at 0",
        ),
        (dict(lengths=np.array([6.0, 4.0, 3.0])), "field 'lengths': must be integers"),
        (dict(step_labels=LABELS[:, :5]), "field 'step_labels': must have shape \\(3, 6\\)"),
    ],
)
def test_bad_step_fields_name_field_sample_and_step(kw, message):
    with pytest.raises(DataError, match=message):
        _ds(**kw)
