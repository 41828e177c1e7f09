"""Source ids (issue 26, item 3): where each sample was recorded, kept through the data set's life.

An optional array of the schema: written and read back, kept by ``subset`` and by a merge,
checked (one line per sample, one id per sample), listed by ``info``, named by ``show``;
files without it read as before.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import DatasetWriter, MotionDataset
from primspace.data.importers import chain_lasa, import_lasa
from primspace.utils.errors import DataError


def _data(n=8, ids=True):
    rng = np.random.default_rng(0)
    return MotionDataset(
        rng.normal(size=(n, 6, 2)),
        labels=np.arange(n) % 2,
        source_ids=[f"robomimic:lift.hdf5:data/demo_{i}" for i in range(n)] if ids else None,
    )


def test_ids_are_stored_read_back_and_kept_by_subset(tmp_path):
    ds = _data()
    back = MotionDataset.load(ds.save(tmp_path / "d.h5"))
    assert list(back.source_ids) == list(ds.source_ids)
    with h5py.File(tmp_path / "d.h5") as f:
        assert h5py.check_string_dtype(f["source_ids"].dtype).encoding == "utf-8"
    part = back.subset([5, 2, 5])
    assert list(part.source_ids) == [
        "robomimic:lift.hdf5:data/demo_5",
        "robomimic:lift.hdf5:data/demo_2",
        "robomimic:lift.hdf5:data/demo_5",
    ]
    assert part.source_id(1) == "robomimic:lift.hdf5:data/demo_2" and _data(ids=False).source_id(3) == "sample 3"
    assert back.summary()["source_ids"] == [
        "robomimic:lift.hdf5:data/demo_0",
        "robomimic:lift.hdf5:data/demo_1",
        "robomimic:lift.hdf5:data/demo_2",
        "...",
        "robomimic:lift.hdf5:data/demo_5",
        "robomimic:lift.hdf5:data/demo_6",
        "robomimic:lift.hdf5:data/demo_7",
    ]


def test_a_file_without_ids_reads_as_before(tmp_path):
    back = MotionDataset.load(_data(ids=False).save(tmp_path / "d.h5"))
    assert back.source_ids is None and "source_ids" not in back.summary()
    with h5py.File(tmp_path / "d.h5") as f:
        assert "source_ids" not in f


def test_a_merge_keeps_the_ids_and_refuses_a_file_without(tmp_path):
    a, b = _data(4), _data(4, ids=False)
    a.save(tmp_path / "a.h5"), b.save(tmp_path / "b.h5")
    with DatasetWriter(
        tmp_path / "m.h5",
        n_samples=8,
        length=6,
        joint_names=a.joint_names,
        label_names=a.label_names,
        with_source_ids=True,
    ) as w:
        w.copy_from(0, tmp_path / "a.h5")
        w.copy_from(4, tmp_path / "a.h5")
    assert list(MotionDataset.load(tmp_path / "m.h5").source_ids) == list(a.source_ids) * 2
    with pytest.raises(DataError, match="source_ids.*missing from a block"):
        with DatasetWriter(
            tmp_path / "n.h5",
            n_samples=4,
            length=6,
            joint_names=a.joint_names,
            label_names=a.label_names,
            with_source_ids=True,
        ) as w:
            w.copy_from(0, tmp_path / "b.h5")
    assert not (tmp_path / "n.h5").exists()


@pytest.mark.parametrize(
    "ids, match",
    [
        (["a"] * 3, r"field 'source_ids': must have shape \(4,\)"),
        (["a", "b\nc", "d", "e"], r"field 'source_ids', sample 1: holds a control character"),
        (["a", "b", "c", "x" * 1001], r"field 'source_ids', sample 3: is 1,001 characters long"),
        (["a", "b", 3, "d"], r"field 'source_ids', sample 2: must be strings, got int"),
    ],
)
def test_bad_ids_are_refused_naming_the_sample(ids, match):
    with pytest.raises(DataError, match=match):
        MotionDataset(np.zeros((4, 3, 1)), source_ids=ids)


def test_info_lists_and_show_names_the_ids(run_cli, tmp_path):
    _data().save(tmp_path / "d.h5")
    res = run_cli("info", tmp_path / "d.h5")
    assert res.code == 0 and "ids      robomimic:lift.hdf5:data/demo_0, " in res.out and ", ..., " in res.out
    as_json = json.loads(run_cli("info", tmp_path / "d.h5", "--json").out)
    assert as_json["source_ids"][-1] == "robomimic:lift.hdf5:data/demo_7"
    res = run_cli("show", tmp_path / "d.h5", "--sample", "6", "--out", tmp_path / "s.png")
    assert res.code == 0 and "(sample 6: robomimic:lift.hdf5:data/demo_6)" in res.out


def test_a_damaged_ids_array_is_one_line(run_cli, tmp_path):
    _data().save(tmp_path / "d.h5")
    with h5py.File(tmp_path / "d.h5", "a") as f:
        del f["source_ids"]
        f["source_ids"] = np.arange(8)
    assert_user_error(run_cli("info", tmp_path / "d.h5"), "d.h5", "source_ids", "must be strings")


def test_lasa_and_its_chains_name_their_demonstrations():
    ds = import_lasa(20, shapes=["Sine", "Angle"])
    assert (
        list(ds.source_ids[:2]) == ["lasa:Sine:demo 0", "lasa:Sine:demo 1"] and ds.source_ids[7] == "lasa:Angle:demo 0"
    )
    chains = chain_lasa(3, seed=4)
    for i, text in enumerate(chains.source_ids):
        pieces = text.split(": ", 1)[1].split(" + ")
        assert text.startswith(f"lasa chain {i} (seed 4): ")
        segments = range(int(chains.step_segments[i].max()) + 1)
        shapes = [chains.label_names[chains.step_labels[i][chains.step_segments[i] == s][0]] for s in segments]
        assert [p.split(" demo ")[0] for p in pieces] == shapes


def test_a_run_on_some_samples_records_their_ids(tmp_path):
    from primspace.model.config import ModelConfig
    from primspace.train import TrainConfig, fit

    data = _data(8)
    run = fit(
        data,
        tmp_path / "run",
        model_config=ModelConfig(latent_dim=2, layer_sizes=(4, 2)),
        train_config=TrainConfig(epochs=1, batch_size=4),
        init="zero",
        indices=[6, 1, 3],
        progress=False,
    )
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["data"]["indices"] == run.indices.tolist()
    assert config["data"]["source_ids"] == [f"robomimic:lift.hdf5:data/demo_{i}" for i in run.indices]
