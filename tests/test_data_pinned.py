"""Pins the data layer's HDF5 format and results, so a refactor provably changes none.

The constants below were recorded from the code *before* the schema-table refactor
(issue 12, "each fact once"). Each digest is a SHA-1 over, per HDF5 dataset: its name,
dtype, shape, maxshape, chunks, compression and options, shuffle, fletcher32, fill
value, layout, filter pipeline, the stored bytes of every chunk (the compressed bytes,
so the compression is pinned too) and the decoded values; and over every attribute's
name, HDF5 type, shape and value. In-memory results (subset, without_images,
load_images, summary) are hashed field by field. Error messages are pinned word for word
(with the temporary directory replaced by ``<tmp>``).

To re-record after an *intended* format change, run this file with
``PRIMSPACE_PIN_RECORD=1`` and ``-s``: it prints the new constants instead of checking.
"""

from __future__ import annotations

import hashlib
import json
import os

import h5py
import numpy as np
import pytest

from primspace.data import DatasetWriter, LazyImages, MotionDataset
from primspace.utils.errors import UserError

RECORD = os.environ.get("PRIMSPACE_PIN_RECORD") == "1"

N, T, J, H, W = 37, 5, 3, 3, 4  # N > 32: saving writes more than one block


def full_dataset(n: int = N, seed: int = 0) -> MotionDataset:
    """Every field the class supports: images, labels (with unknowns), params, all names."""
    rng = np.random.default_rng(seed)
    return MotionDataset(
        motor=rng.normal(size=(n, T, J)) * 10.0,
        images=rng.integers(0, 256, size=(n, T, H, W, 3), dtype=np.uint8),
        labels=np.array([(i % 4) - 1 for i in range(n)]),
        params=rng.uniform(-1, 1, size=(n, 2)),
        joint_names=["shoulder", "elbow", "wrist"],
        label_names=["reach", "push", "lift"],
        param_names=["block_x", "block_y"],
        dt=0.04,
        source="pinned test data",
    )


# ---------------------------------------------------------------------------- digests


def _update(h, *parts) -> None:
    for part in parts:
        if isinstance(part, np.ndarray):
            h.update(repr((part.dtype.str, part.shape)).encode())
            if part.dtype.kind == "O":
                h.update(repr([v.decode() if isinstance(v, bytes) else v for v in part.reshape(-1)]).encode())
            else:
                h.update(np.ascontiguousarray(part).tobytes())
        elif isinstance(part, bytes):
            h.update(part)
        else:
            h.update(repr(part).encode())
        h.update(b"\x00")


def _filters(dset: h5py.Dataset) -> list:
    plist = dset.id.get_create_plist()
    return [tuple(plist.get_filter(i)[::2]) for i in range(plist.get_nfilters())]


def dataset_node_digest(dset: h5py.Dataset) -> str:
    h = hashlib.sha1()
    plist = dset.id.get_create_plist()
    _update(
        h,
        dset.name,
        dset.dtype.str,
        dset.shape,
        dset.maxshape,
        dset.chunks,
        dset.compression,
        dset.compression_opts,
        dset.shuffle,
        dset.fletcher32,
        dset.scaleoffset,
        np.asarray(dset.fillvalue),
        plist.get_layout(),
        _filters(dset),
    )
    if dset.chunks is not None:
        for k in range(dset.id.get_num_chunks()):
            info = dset.id.get_chunk_info(k)
            mask, chunk = dset.id.read_direct_chunk(info.chunk_offset)
            _update(h, info.chunk_offset, mask, chunk)
    _update(h, np.asarray(dset[()]))
    return h.hexdigest()


def attrs_digest(f: h5py.File) -> str:
    h = hashlib.sha1()
    for name in sorted(f.attrs):
        aid = f.attrs.get_id(name)
        string = h5py.check_string_dtype(aid.dtype)
        _update(h, name, aid.dtype.str, aid.shape, None if string is None else (string.encoding, string.length))
        _update(h, np.asarray(f.attrs[name]))
    return h.hexdigest()


def file_digest(path) -> dict:
    """One digest per dataset, one over the attributes, the list of nodes, and the bytes.

    ``file`` (the SHA-1 of the whole file) is compared only under the HDF5 library it
    was recorded with (:data:`RECORDED_HDF5`): another libhdf5 may lay out the same
    content differently.
    """
    with open(path, "rb") as fh:
        whole = hashlib.sha1(fh.read()).hexdigest()
    with h5py.File(path, "r") as f:
        out = {"nodes": sorted(f.keys()), "attrs": attrs_digest(f), "file": whole}
        for name in sorted(f.keys()):
            out[name] = dataset_node_digest(f[name])
    return out


def memory_digest(ds: MotionDataset) -> str:
    """A dataset's fields, as the class holds them (images read through whatever view)."""
    h = hashlib.sha1()
    images = ds.images
    kind = None if images is None else type(images).__name__
    _update(h, kind, ds.motor)
    _update(h, None if images is None else np.asarray(images))
    if isinstance(images, LazyImages):
        _update(h, images._index, images.path is not None)
    _update(h, ds.labels, ds.params, ds.joint_names, ds.label_names, ds.param_names, ds.dt, ds.source)
    _update(h, None if ds.path is None else os.path.basename(ds.path))
    return h.hexdigest()


def summary_digest(ds: MotionDataset) -> str:
    s = ds.summary()
    s["path"] = None if s["path"] is None else os.path.basename(s["path"])
    assert s.pop("steps") is None  # new in 0.4: the step fields' summary; these files have none
    return hashlib.sha1(json.dumps(s, sort_keys=True).encode()).hexdigest()


# -------------------------------------------------------------------------- scenarios


def _writer(path, n, **kw):
    settings = dict(
        n_samples=n,
        length=T,
        joint_names=["shoulder", "elbow", "wrist"],
        image_size=(H, W),
        label_names=["reach", "push", "lift"],
        param_names=["block_x", "block_y"],
        dt=0.04,
        source="merged",
    )
    settings.update(kw)
    return DatasetWriter(path, **settings)


def scenarios(tmp_path) -> dict:
    """Every pinned result, by name."""
    out: dict = {}
    ds = full_dataset()
    full = ds.save(tmp_path / "full.h5")
    out["save full"] = file_digest(full)
    out["save full, gzip 9"] = file_digest(ds.save(tmp_path / "full9.h5", compression_level=9))
    bare = MotionDataset(np.random.default_rng(1).normal(size=(4, T, 2)))
    out["save bare"] = file_digest(bare.save(tmp_path / "bare.h5"))
    out["memory bare"] = memory_digest(bare)
    out["memory full"] = memory_digest(ds)

    back = MotionDataset.load(full)
    out["load full"] = memory_digest(back)
    out["load bare"] = memory_digest(MotionDataset.load(tmp_path / "bare.h5"))
    out["summary full"] = summary_digest(back)
    out["summary bare"] = summary_digest(bare)

    idx = [30, 2, 35, 7, 0, 33]
    sub = back.subset(idx)
    out["subset of file"] = memory_digest(sub)
    out["subset of memory"] = memory_digest(ds.subset(idx))
    mask = np.zeros(N, bool)
    mask[[1, 4, 36]] = True
    out["subset by mask"] = memory_digest(back.subset(mask))
    out["subset of subset"] = memory_digest(sub.subset([5, 1]))
    out["save subset"] = file_digest(sub.save(tmp_path / "sub.h5"))
    out["without_images"] = memory_digest(back.without_images())
    out["save without_images"] = file_digest(back.without_images().save(tmp_path / "noimg.h5"))
    out["load_images"] = memory_digest(back.load_images())

    # merging: two shards copied raw, one re-encoded (other compression), one written
    a = ds.subset(np.arange(0, 20)).save(tmp_path / "a.h5")
    b = ds.subset(np.arange(20, 30)).save(tmp_path / "b.h5", compression_level=1)
    with _writer(tmp_path / "merged.h5", N) as w:
        assert w.copy_from(0, a) == 20
        assert w.copy_from(20, b) == 10
        rest = ds.subset(np.arange(30, N))
        w.write(30, motor=rest.motor, images=rest.images, labels=rest.labels, params=rest.params)
    out["merge"] = file_digest(tmp_path / "merged.h5")
    out["load merge"] = memory_digest(MotionDataset.load(tmp_path / "merged.h5"))

    # a writer without images, labels given by flag only (fill value -1 never overwritten)
    with _writer(
        tmp_path / "flags.h5",
        3,
        image_size=None,
        label_names=(),
        param_names=(),
        with_labels=True,
        with_params=False,
        source="",
    ) as w:
        w.write(0, motor=np.arange(3 * T * 3, dtype=float).reshape(3, T, 3), labels=[-1, -1, -1])
    out["writer flags"] = file_digest(tmp_path / "flags.h5")

    # a file as older or other tools write it: no attributes at all
    with h5py.File(tmp_path / "plain.h5", "w") as f:
        f.create_dataset("motor", data=np.arange(2 * T * 2, dtype=np.float64).reshape(2, T, 2))
        f.create_dataset("labels", data=np.array([1, 0], np.int64))
        f.create_dataset("params", data=np.ones((2, 1)))
    out["load plain"] = memory_digest(MotionDataset.load(tmp_path / "plain.h5"))
    return out


# ------------------------------------------------------------------- error messages


def _message(tmp_path, fn) -> str:
    try:
        fn()
    except UserError as exc:
        return f"{type(exc).__name__}: " + str(exc).replace(str(tmp_path), "<tmp>")
    raise AssertionError("no error raised")


def _raw(path, attrs=None, **arrays):
    with h5py.File(path, "w") as f:
        for name, value in arrays.items():
            f.create_dataset(name, data=value)
        f.attrs.update(attrs or {})
    return path


def error_cases(tmp_path) -> list:
    z = np.zeros
    good = full_dataset(6).save(tmp_path / "good.h5")
    small = full_dataset(6)
    inf = z((2, 3, 2))
    inf[1, 2, 1] = np.inf
    cases = [
        lambda: MotionDataset(z((3, 4))),
        lambda: MotionDataset(z((0, 4, 2))),
        lambda: MotionDataset(z((2, 1, 2))),
        lambda: MotionDataset(z((2, 4, 0))),
        lambda: MotionDataset(inf),
        lambda: MotionDataset(z((2, 4, 2)), joint_names=["a"]),
        lambda: MotionDataset(z((2, 4, 2)), joint_names=["a", "a"]),
        lambda: MotionDataset(z((2, 4, 2)), images=z((2, 4, 3, 3, 3), np.float32)),
        lambda: MotionDataset(z((2, 4, 2)), images=z((2, 4, 3, 3), np.uint8)),
        lambda: MotionDataset(z((2, 4, 2)), images=z((3, 4, 3, 3, 3), np.uint8)),
        lambda: MotionDataset(z((2, 4, 2)), images=z((2, 5, 3, 3, 3), np.uint8)),
        lambda: MotionDataset(z((2, 4, 2)), labels=[0.5, 1]),
        lambda: MotionDataset(z((2, 4, 2)), labels=[0, 1, 1]),
        lambda: MotionDataset(z((2, 4, 2)), labels=[0, 2], label_names=["a", "b"]),
        lambda: MotionDataset(z((2, 4, 2)), labels=[0, -2]),
        lambda: MotionDataset(z((2, 4, 2)), labels=np.array([0, 2**40])),
        lambda: MotionDataset(z((2, 4, 2)), params=z((2,))),
        lambda: MotionDataset(z((2, 4, 2)), params=z((3, 1))),
        lambda: MotionDataset(z((2, 4, 2)), params=np.array([[1.0], [np.nan]])),
        lambda: MotionDataset(z((2, 4, 2)), params=np.array([[1.0], [1e300]])),
        lambda: MotionDataset(z((2, 4, 2)), params=z((2, 2)), param_names=["x"]),
        lambda: MotionDataset(z((2, 4, 2)), dt=0),
        lambda: MotionDataset(z((2, 4, 2)), dt=np.nan),
        lambda: MotionDataset(np.array([["a"]])),
        lambda: small.subset([0, 6]),
        lambda: small.subset([-1]),
        lambda: small.subset([]),
        lambda: small.subset([0.5]),
        lambda: small.subset(np.ones(5, bool)),
        lambda: MotionDataset.load(tmp_path / "missing.h5"),
        lambda: MotionDataset.load(tmp_path),
        lambda: MotionDataset.load(_raw(tmp_path / "nomotor.h5", labels=z(2, np.int32))),
        lambda: MotionDataset.load(_raw(tmp_path / "intmotor.h5", motor=z((2, 3, 1), np.int64))),
        lambda: MotionDataset.load(_raw(tmp_path / "img.h5", motor=z((2, 3, 1)), images=z((2, 3, 2, 2, 3)))),
        lambda: MotionDataset.load(_raw(tmp_path / "lab.h5", motor=z((2, 3, 1)), labels=np.array([0, -3]))),
        lambda: MotionDataset.load(_raw(tmp_path / "labf.h5", motor=z((2, 3, 1)), labels=np.array([0.0, 1.0]))),
        lambda: MotionDataset.load(_raw(tmp_path / "par.h5", motor=z((2, 3, 1)), params=z((3, 1)))),
        lambda: MotionDataset.load(_raw(tmp_path / "jn.h5", {"joint_names": ["a", "b"]}, motor=z((2, 3, 1)))),
        lambda: MotionDataset.load(
            _raw(tmp_path / "pn.h5", {"param_names": ["a", "b"]}, motor=z((2, 3, 1)), params=z((2, 1)))
        ),
        lambda: MotionDataset.load(_raw(tmp_path / "dt.h5", {"dt": -1.0}, motor=z((2, 3, 1)))),
        lambda: MotionDataset.load(_raw(tmp_path / "dts.h5", {"dt": "x"}, motor=z((2, 3, 1)))),
        lambda: MotionDataset.load(_raw(tmp_path / "ver.h5", {"schema_version": 3}, motor=z((2, 3, 1)))),
        lambda: MotionDataset.load(_raw(tmp_path / "ver0.h5", {"schema_version": 0}, motor=z((2, 3, 1)))),
    ]
    with h5py.File(tmp_path / "grp.h5", "w") as f:
        f.create_dataset("motor", data=z((2, 3, 1)))
        f.create_group("labels")
    cases.append(lambda: MotionDataset.load(tmp_path / "grp.h5"))
    with h5py.File(tmp_path / "grpimg.h5", "w") as f:
        f.create_dataset("motor", data=z((2, 3, 1)))
        f.create_group("images")
    cases.append(lambda: MotionDataset.load(tmp_path / "grpimg.h5"))

    def writer_case(block=None, copy=None, **kw):
        def run():
            with _writer(tmp_path / "w.h5", 6, **kw) as w:
                if block is not None:
                    w.write(**block)
                if copy is not None:
                    w.copy_from(0, copy)

        return run

    m = small.motor
    full_block = dict(start=0, motor=m, images=small.images, labels=small.labels, params=small.params)
    cases += [
        writer_case(n_samples=0),
        writer_case(length=1),
        writer_case(joint_names=[]),
        writer_case(dict(full_block, start=1)),
        writer_case(dict(full_block, images=None)),
        writer_case(dict(full_block, labels=None)),
        writer_case(dict(full_block, params=None)),
        writer_case(dict(full_block, motor=m[:, :4])),
        writer_case(dict(full_block, images=small.images[:, :, :2])),
        writer_case(dict(full_block, motor=z((0, T, J)))),
        writer_case(full_block, image_size=None),
        writer_case(
            dict(start=0, motor=m, images=None, labels=small.labels, params=small.params),
            image_size=None,
            with_labels=False,
        ),
        writer_case(
            dict(start=0, motor=m[:3], images=small.images[:3], labels=small.labels[:3], params=small.params[:3])
        ),
        writer_case(copy=good, joint_names=["a", "b", "c"]),
        writer_case(copy=good, dt=0.5),
        writer_case(copy=good, label_names=["x", "y", "z"]),
        writer_case(copy=good, param_names=["u", "v"]),
        writer_case(copy=good, image_size=(2, 2)),
        writer_case(copy=good, length=4),
        writer_case(copy=good, n_samples=5),
        writer_case(copy=tmp_path / "missing.h5"),
    ]
    return cases


# ------------------------------------------------------------------------ the pins

#: The libhdf5 the whole-file digests ("file") were recorded with.
RECORDED_HDF5 = "2.0.0"

# Re-recorded for schema 2 (issue 24): fletcher32 on motor/labels/params (chunked, with a
# checksum filter) and schema_version 2 change the "attrs", "file", "motor", "labels" and
# "params" digests of the saved files; images and every in-memory result are unchanged.
PINNED = {
    "load bare": "039d9e4eda0ebbf00d73a0317ba83661730d3e4a",
    "load full": "f444f839ef08aec67a3e15a24552a1d7bfcfc0f5",
    "load merge": "841e55de5a2f203b8b029162e9035ee2f610e749",
    "load plain": "e714f66fce9f23befda290d161a2ffb3aac0413e",
    "load_images": "8315630f0c072ab5eac60a8d918e57ccbf900e73",
    "memory bare": "33472f4fc5a3233194ba53876de3b9da65f066d0",
    "memory full": "efdf470ad8151012ecea868dba7d3a05193c347b",
    "merge": {
        "attrs": "7b6ac1b0f9c8f6b8f3ee56b0be1500278c4a8ee4",
        "file": "07b871d7d6858873ef84858e91e2cfd9de340056",
        "images": "a095375621fe1e57e1765668caf73697d8162107",
        "labels": "41f7fa1f5742bbbe55ed14903acab75d91af7379",
        "motor": "57bf9c36bde93f4f3f18ffe734b94e4575445244",
        "nodes": ["images", "labels", "motor", "params"],
        "params": "972676da9aa258ce79b6a98302fd4c21ee7341e3",
    },
    "save bare": {
        "attrs": "f9b0099e08498730251d0e33d5519b38fc9d4dfb",
        "file": "492686e692ebe8a5eaf569919d56299f0c69f790",
        "motor": "b7a2429205242b7b8ff1f31b3877b88d14d4af22",
        "nodes": ["motor"],
    },
    "save full": {
        "attrs": "38d278782a897aa7734a94fbc34d7bf1cfbbaa09",
        "file": "fb6b2c0a0a9896d8fca5f790e6cd3b98aefc61af",
        "images": "a095375621fe1e57e1765668caf73697d8162107",
        "labels": "41f7fa1f5742bbbe55ed14903acab75d91af7379",
        "motor": "57bf9c36bde93f4f3f18ffe734b94e4575445244",
        "nodes": ["images", "labels", "motor", "params"],
        "params": "972676da9aa258ce79b6a98302fd4c21ee7341e3",
    },
    "save full, gzip 9": {
        "attrs": "38d278782a897aa7734a94fbc34d7bf1cfbbaa09",
        "file": "9750f308bc2d5d511d345992df0d4c46c1464b44",
        "images": "318358fd7088f7b576f3368b368df87a2d8d10e9",
        "labels": "41f7fa1f5742bbbe55ed14903acab75d91af7379",
        "motor": "57bf9c36bde93f4f3f18ffe734b94e4575445244",
        "nodes": ["images", "labels", "motor", "params"],
        "params": "972676da9aa258ce79b6a98302fd4c21ee7341e3",
    },
    "save subset": {
        "attrs": "38d278782a897aa7734a94fbc34d7bf1cfbbaa09",
        "file": "d57a31b441c335fff44297cc2cf8fd6736258473",
        "images": "0a96549ad7c543209f3336a4b7e436f92d94d449",
        "labels": "f61bfbbb4203e2d466aca56f635882275b4cc84d",
        "motor": "a3dcc0bfa373cc874ddbc2e251ba614b1819372d",
        "nodes": ["images", "labels", "motor", "params"],
        "params": "7d6ca87a3afcd8becb186ff39c0ed0a9d38b47e8",
    },
    "save without_images": {
        "attrs": "38d278782a897aa7734a94fbc34d7bf1cfbbaa09",
        "file": "b3c78c59249f808d5ba27825e1775296f2dd3ed2",
        "labels": "41f7fa1f5742bbbe55ed14903acab75d91af7379",
        "motor": "57bf9c36bde93f4f3f18ffe734b94e4575445244",
        "nodes": ["labels", "motor", "params"],
        "params": "972676da9aa258ce79b6a98302fd4c21ee7341e3",
    },
    "subset by mask": "acf7dce61dd904a64eaa7d8b8f7e8210ea3c18a2",
    "subset of file": "1e6f71674b0fe09d1a514a69c751748f1076cd14",
    "subset of memory": "d5631f17e1c11a084c62bc4d867c60852aa1b1f2",
    "subset of subset": "31a84cf9ac801228ed4c0edb7cd02f3e392d6e95",
    "summary bare": "92708e124dbf10553c255d8dcaa00f23f2796c53",
    "summary full": "5c96e38b745031d6b9d50a4c9c7bd633f4ad5292",
    "without_images": "4742a12ee69ad8c18dc893cbb454e529bbe93620",
    "writer flags": {
        "attrs": "8f38a9b5f5f072d0d3f0cfb50420bfeaf2ce2594",
        "file": "e7da03d386cf7ce5dd3c6a69a5be4b8a13f1222a",
        "labels": "82134a46abc11917b451da3578c858d0606ba868",
        "motor": "37d66febbf527f84cc35530892cd7f70fc60386f",
        "nodes": ["labels", "motor"],
    },
}

PINNED_ERRORS = [
    "DataError: field 'motor': must have shape (N, T, J), got rank 2 (3, 4)",
    "DataError: field 'motor': holds no samples",
    "DataError: field 'motor': sequences need at least 2 time steps, got T=1",
    "DataError: field 'motor': has no joints (J=0)",
    "DataError: field 'motor', sample 1: contains NaN or inf (step 2, joint 1)",
    "DataError: field 'joint_names': 1 joint names for J=2 joints",
    "DataError: field 'joint_names': joint names are not unique",
    "DataError: field 'images': images must be uint8, got float32",
    "DataError: field 'images': must have shape (N, T, H, W, 3), got (2, 4, 3, 3)",
    "DataError: field 'images': 3 samples but motor has 2",
    "DataError: field 'images': 5 time steps but motor has T=4",
    "DataError: field 'labels': labels must be integers, got float64",
    "DataError: field 'labels': must have shape (2,) to match motor, got (3,)",
    "DataError: field 'labels', sample 1: label 2 out of range [-1, 1] (2 label names)",
    "DataError: field 'labels', sample 1: label -2 out of range [-1, 0] (1 label names)",
    "DataError: field 'labels', sample 1: label 1099511627776 is not a primitive index (it does not fit in int32)",
    "DataError: field 'params': must have shape (2, P), got (2,)",
    "DataError: field 'params': must have shape (2, P), got (3, 1)",
    "DataError: field 'params', sample 1: contains NaN or inf",
    "DataError: field 'params', sample 1: value 1e+300 exceeds the float32 range (magnitude at most 3.40282e+38) (column 0)",
    "DataError: field 'param_names': 1 names for P=2 params",
    "DataError: field 'dt': must be a positive number, got 0.0",
    "DataError: field 'dt': must be a positive number, got nan",
    "DataError: field 'motor': must be numbers, got <U1",
    "UserError: sample index 6 out of range for 6 samples",
    "UserError: sample index -1 out of range for 6 samples",
    "UserError: an empty selection of samples",
    "UserError: sample indices must be integers, got float64",
    "UserError: boolean mask of shape (5,) for 6 samples",
    "DataError: <tmp>/missing.h5: no such file",
    "DataError: <tmp>: is a directory, not an HDF5 data set file",
    "DataError: <tmp>/nomotor.h5, field 'motor': missing (every data set needs joint values)",
    "DataError: <tmp>/intmotor.h5, field 'motor': must be floating point, got int64",
    "DataError: <tmp>/img.h5, field 'images': must be uint8, got float64",
    "DataError: <tmp>/lab.h5, field 'labels', sample 1: label -3 out of range [-1, 0] (1 label names)",
    "DataError: <tmp>/labf.h5, field 'labels': labels must be integers, got float64",
    "DataError: <tmp>/par.h5, field 'params': must have shape (2, P), got (3, 1)",
    "DataError: <tmp>/jn.h5, field 'joint_names': 2 joint names for J=1 joints",
    "DataError: <tmp>/pn.h5, field 'param_names': 2 names for P=1 params",
    "DataError: <tmp>/dt.h5, field 'dt': must be a positive number, got -1.0",
    "DataError: <tmp>/dts.h5, field 'dt': must be one number, got 1 value(s) of type <U1",
    "DataError: <tmp>/ver.h5, field 'schema_version': schema version 3 is newer than this primspace reads (2)",
    "DataError: <tmp>/ver0.h5, field 'schema_version': must be a positive integer, got 0",
    "DataError: <tmp>/grp.h5, field 'labels': is not an array",
    "DataError: <tmp>/grpimg.h5, field 'images': is not an array",
    "DataError: <tmp>/w.h5, field 'motor': a data set needs N >= 1, T >= 2 and J >= 1, got N=0, T=5, J=3",
    "DataError: <tmp>/w.h5, field 'motor': a data set needs N >= 1, T >= 2 and J >= 1, got N=6, T=1, J=3",
    "DataError: <tmp>/w.h5, field 'motor': a data set needs N >= 1, T >= 2 and J >= 1, got N=6, T=5, J=0",
    "DataError: <tmp>/w.h5, field 'motor': block of 6 samples at 1 does not fit in N=6",
    "DataError: <tmp>/w.h5, field 'images', sample 0: missing from a block",
    "DataError: <tmp>/w.h5, field 'labels', sample 0: missing from a block",
    "DataError: <tmp>/w.h5, field 'params', sample 0: missing from a block",
    "DataError: field 'images': 5 time steps but motor has T=4",
    "DataError: <tmp>/w.h5, field 'images', sample 0: block shape (2, 4) does not match the file's (3, 4)",
    "DataError: <tmp>/w.h5, field 'motor': block of 0 samples at 0 does not fit in N=6",
    "DataError: <tmp>/w.h5, field 'images', sample 0: given but the file has none",
    "DataError: <tmp>/w.h5, field 'labels', sample 0: given but the file has none",
    "DataError: <tmp>/w.h5, field 'motor', sample 3: 3 samples never written",
    "DataError: <tmp>/good.h5, field 'joint_names': ['shoulder', 'elbow', 'wrist'] does not match the file's ['a', 'b', 'c']",
    "DataError: <tmp>/good.h5, field 'dt': 0.04 does not match the file's 0.5",
    "DataError: <tmp>/good.h5, field 'label_names': ['reach', 'push', 'lift'] does not match the file's ['x', 'y', 'z']",
    "DataError: <tmp>/good.h5, field 'param_names': ['block_x', 'block_y'] does not match the file's ['u', 'v']",
    "DataError: <tmp>/good.h5, field 'images': cannot be copied into <tmp>/w.h5: block shape (3, 4) does not match the file's (2, 2)",
    "DataError: <tmp>/good.h5, field 'motor': cannot be copied into <tmp>/w.h5: block shape (5, 3) does not match the file's (4, 3)",
    "DataError: <tmp>/good.h5, field 'motor': cannot be copied into <tmp>/w.h5: block of 6 samples at 0 does not fit in N=5",
    "DataError: <tmp>/missing.h5: no such file",
]


def test_file_layout_and_results_are_pinned(tmp_path):
    got = scenarios(tmp_path)
    if RECORD:
        print(f"\nRECORDED_HDF5 = {h5py.version.hdf5_version!r}")
        print("\nPINNED = " + json.dumps(got, indent=4, sort_keys=True))
        return
    same_library = h5py.version.hdf5_version == RECORDED_HDF5
    assert set(got) == set(PINNED)
    for name in PINNED:
        want, have = PINNED[name], got[name]
        if isinstance(want, dict) and not same_library:
            want, have = dict(want, file=None), dict(have, file=None)
        assert have == want, name


def test_error_messages_are_pinned(tmp_path):
    got = [_message(tmp_path, fn) for fn in error_cases(tmp_path)]
    if RECORD:
        print("\nPINNED_ERRORS = " + json.dumps(got, indent=4))
        return
    assert got == PINNED_ERRORS


def test_save_equals_the_layout_written_by_hand(tmp_path):
    """The format as documented (docs/data.md), written with h5py alone, equals ``save``."""
    ds = full_dataset(6)
    path = ds.save(tmp_path / "saved.h5")
    by_hand = tmp_path / "by_hand.h5"
    s = h5py.string_dtype()
    with h5py.File(by_hand, "w") as f:
        f.attrs["schema_version"] = 2  # schema 2: fletcher32 on motor/labels/params
        f.attrs["joint_names"] = np.array(ds.joint_names, dtype=s)
        f.attrs["label_names"] = np.array(ds.label_names, dtype=s)
        f.attrs["param_names"] = np.array(ds.param_names, dtype=s)
        f.attrs["dt"] = ds.dt
        f.attrs["source"] = ds.source
        # schema 2: fletcher32 on motor/labels/params, in chunks of whole samples (6 fit in one)
        f.create_dataset("motor", data=ds.motor.astype(np.float32), chunks=(6, T, J), fletcher32=True)
        f.create_dataset("labels", data=ds.labels.astype(np.int32), fillvalue=-1, chunks=(6,), fletcher32=True)
        f.create_dataset("params", data=ds.params.astype(np.float32), chunks=(6, 2), fletcher32=True)
        f.create_dataset("images", data=ds.images, chunks=(1, T, H, W, 3), compression="gzip", compression_opts=4)
    assert dict(file_digest(path), file=None) == dict(file_digest(by_hand), file=None)


# ------------------------------------------------------------------ index files

#: ``read_indices`` as it was in ``primspace.train`` before it moved to
#: ``primspace.data.indices``: each implementation listed here must give these.
READ_INDICES = ["primspace.train", "primspace.data.indices"]


def index_files(d):
    """Write index files into ``d``; return ``[(name, path, data)]``, data: "file", "memory" or None."""
    cases = []

    def text(name, content, data="file"):
        p = d / name
        p.write_text(content)
        cases.append((name, p, data))

    def npy(name, arr, data="file"):
        p = d / name
        np.save(p, arr)
        cases.append((name, p, data))

    text("ok.txt", "3, 1 # first\n\n 0,2\n# only a comment\n4")
    text("ok-nodata.txt", "3 1 -7 99", data=None)
    text("float.txt", "1.5 2")
    text("word.txt", "1 two")
    text("empty.txt", "")
    text("comment.txt", "# nothing\n")
    text("dup.txt", "1 2 1")
    text("range.txt", "0 5 9")
    text("neg.txt", "0 -1")
    text("range-mem.txt", "0 6", data="memory")
    text("UPPER.NPY.txt", "1")
    npy("ok.npy", np.array([4, 0, 2], np.int32))
    npy("u8.npy", np.array([1, 0], np.uint8))
    npy("u64.npy", np.array([0, 2**64 - 1], np.uint64))
    npy("2d.npy", np.zeros((2, 2), np.int64))
    npy("f.npy", np.array([1.0]))
    npy("b.npy", np.array([True]))
    npy("e.npy", np.array([], np.int64))
    npy("s.npy", np.array(["1"]))
    npy("obj.npy", np.array([1, None], dtype=object))
    npy("scalar.npy", np.int64(3))
    npy("dup.npy", np.array([1, 1]))
    npy("range.npy", np.array([0, 6]))
    up = d / "UP.NPY"
    np.save(d / "tmp_up.npy", np.array([1, 2]))
    (d / "tmp_up.npy").rename(up)
    cases.append(("UP.NPY", up, "file"))
    bad = d / "bad.npy"
    bad.write_bytes(b"not numpy")
    cases.append(("bad.npy", bad, "file"))
    latin = d / "latin.txt"
    latin.write_bytes(b"1 \xe9")
    cases.append(("latin.txt", latin, "file"))
    cases.append(("missing.txt", d / "missing.txt", "file"))
    (d / "dir.txt").mkdir()
    cases.append(("dir.txt", d / "dir.txt", "file"))
    return cases


PINNED_READ_INDICES = [
    ["ok.txt", "ok", "int64", [3, 1, 0, 2, 4]],
    ["ok-nodata.txt", "ok", "int64", [3, 1, -7, 99]],
    [
        "float.txt",
        "DataError",
        "<tmp>/float.txt, field 'indices': cannot read sample indices ('1.5' is not a whole number)",
    ],
    [
        "word.txt",
        "DataError",
        "<tmp>/word.txt, field 'indices': cannot read sample indices ('two' is not a whole number)",
    ],
    ["empty.txt", "DataError", "<tmp>/empty.txt, field 'indices': must be a non-empty list of integers"],
    ["comment.txt", "DataError", "<tmp>/comment.txt, field 'indices': must be a non-empty list of integers"],
    ["dup.txt", "DataError", "<tmp>/dup.txt, field 'indices': lists a sample more than once"],
    [
        "range.txt",
        "DataError",
        "<tmp>/range.txt, field 'indices': sample 9 is out of range for the 6 samples of <tmp>/data.h5",
    ],
    [
        "neg.txt",
        "DataError",
        "<tmp>/neg.txt, field 'indices': sample -1 is out of range for the 6 samples of <tmp>/data.h5",
    ],
    ["range-mem.txt", "DataError", "<tmp>/range-mem.txt, field 'indices': sample 6 is out of range for the 6 samples"],
    ["UPPER.NPY.txt", "ok", "int64", [1]],
    ["ok.npy", "ok", "int64", [4, 0, 2]],
    ["u8.npy", "ok", "int64", [1, 0]],
    [
        "u64.npy",
        "DataError",
        "<tmp>/u64.npy, field 'indices': sample 18446744073709551615 is out of range for the 6 samples of <tmp>/data.h5",
    ],
    ["2d.npy", "DataError", "<tmp>/2d.npy, field 'indices': must be a non-empty list of integers"],
    ["f.npy", "DataError", "<tmp>/f.npy, field 'indices': must be a non-empty list of integers"],
    ["b.npy", "DataError", "<tmp>/b.npy, field 'indices': must be a non-empty list of integers"],
    ["e.npy", "DataError", "<tmp>/e.npy, field 'indices': must be a non-empty list of integers"],
    ["s.npy", "DataError", "<tmp>/s.npy, field 'indices': must be a non-empty list of integers"],
    [
        "obj.npy",
        "DataError",
        "<tmp>/obj.npy, field 'indices': cannot read sample indices (Object arrays cannot be loaded when allow_pickle=False)",
    ],
    ["scalar.npy", "DataError", "<tmp>/scalar.npy, field 'indices': must be a non-empty list of integers"],
    ["dup.npy", "DataError", "<tmp>/dup.npy, field 'indices': lists a sample more than once"],
    [
        "range.npy",
        "DataError",
        "<tmp>/range.npy, field 'indices': sample 6 is out of range for the 6 samples of <tmp>/data.h5",
    ],
    ["UP.NPY", "ok", "int64", [1, 2]],
    [
        "bad.npy",
        "DataError",
        "<tmp>/bad.npy, field 'indices': cannot read sample indices (This file contains pickled (object) data. If you trust the file you can load it unsafely using the `allow_pickle=` keyword argument or `pickle.load()`.)",
    ],
    [
        "latin.txt",
        "DataError",
        "<tmp>/latin.txt, field 'indices': cannot read sample indices ('utf-8' codec can't decode byte 0xe9 in position 2: unexpected end of data)",
    ],
    ["missing.txt", "DataError", "<tmp>/missing.txt, field 'indices': no such file"],
    ["dir.txt", "DataError", "<tmp>/dir.txt, field 'indices': no such file"],
]


@pytest.mark.parametrize("module", READ_INDICES)
def test_read_indices_is_pinned(tmp_path, module):
    import importlib

    read_indices = importlib.import_module(module).read_indices
    data = {
        "file": MotionDataset(np.zeros((6, 3, 1)), path=tmp_path / "data.h5"),
        "memory": MotionDataset(np.zeros((6, 3, 1))),
        None: None,
    }
    got = []
    for name, path, which in index_files(tmp_path):
        try:
            r = read_indices(path, data[which])
            got.append([name, "ok", str(r.dtype), r.tolist()])
        except UserError as exc:
            got.append([name, type(exc).__name__, str(exc).replace(str(tmp_path), "<tmp>")])
    assert got == PINNED_READ_INDICES


# ------------------------------------------------------------------------ importers

PINNED_IMPORTS = {
    "plain": "898ecb734efb9241ad811658630e650383ced2a2",
    "arr": "738754dde4752d4ac079a0fdeb5ed75615b54e8c",
    "lengths": "2938c4de604aafb05b4996c57e2b056c6f9a3893",
    "full": "542d0893dd2d46300ec39b3e4f66bcbef16b6135",
    "intlabels": "1d474ef5e72f553cbfb6262bc018fe08e7a0c1d2",
    "intlabels_names": "0bea07b2e79cbe2c19b9b26e673356079e934395",
    "names_only": "676e4d95cd1fde82c5d6eef1551593ee71a08af5",
    "strlab_nonames": "77aaf98e68c8af4fdfbc3f107288fc844a1de728",
    "badlab": "<d>/badlab.npz, field 'labels', sample 0: label np.str_('q') is not among label_names",
    "badparams": "<d>/badparams.npz, field 'params': must have shape (3, P), got (2, 2)",
    "badjn": "<d>/badjn.npz, field 'joint_names': 1 joint names for J=2 joints",
    "baddt": "<d>/baddt.npz, field 'dt': must be one positive number, got 2 value(s) of type float64",
    "negdt": "<d>/negdt.npz, field 'dt': must be a positive number, got -1.0",
    "floatlab": "<d>/floatlab.npz, field 'labels': must be integers or strings, got float64",
    "big": "<d>/big.npz, field 'motor', sample 0: value 1e+39 exceeds the float32 range (magnitude at most 3.40282e+38) (step 0, joint 0)",
    "csv": "1ea57731023752a6d9daaffb9f02c839251d5aef",
    "csv clock": "<d>/csv/c.csv, field 't', sample 1: line 3: time 0 does not come after 0 on line 2 (time stamps must strictly increase)",
    "csv nan clock": "<d>/csv/c.csv, field 't', sample 1: line 3: time stamp 'nan' is not a finite number",
}


def test_importers_are_pinned(tmp_path):
    """npz and CSV imports: the data sets made (digests) and the errors (messages)."""
    from primspace.data.importers import import_csv_folder, import_npz

    rng = np.random.default_rng(0)
    seqs = [rng.normal(size=(t, 2)) for t in (5, 8, 11)]

    def m():
        return rng.normal(size=(3, 7, 2))

    cases = {
        "plain": dict(motor=m()),
        "arr": {f"arr_{i}": s for i, s in enumerate(seqs)},
        "lengths": dict(motor=np.concatenate(seqs), lengths=np.array([5, 8, 11])),
        "full": dict(
            motor=m(),
            labels=np.array(["b", "a", "b"]),
            label_names=np.array(["a", "b", "c"]),
            joint_names=np.array(["x", "y"]),
            params=rng.normal(size=(3, 2)),
            param_names=np.array(["u", "v"]),
            dt=0.1,
        ),
        "intlabels": dict(motor=m(), labels=np.array([0, -1, 2])),
        "intlabels_names": dict(motor=m(), labels=np.array([0, -1, 1]), label_names=np.array([10, 20])),
        "names_only": dict(motor=m(), label_names=np.array(["a"])),
        "strlab_nonames": dict(motor=m(), labels=np.array(["z", "a", "z"])),
        "badlab": dict(motor=m(), labels=np.array(["q", "a", "b"]), label_names=np.array(["a", "b"])),
        "badparams": dict(motor=m(), params=np.ones((2, 2))),
        "badjn": dict(motor=m(), joint_names=np.array(["x"])),
        "baddt": dict(motor=m(), dt=np.array([1.0, 2.0])),
        "negdt": dict(motor=m(), dt=-1.0),
        "floatlab": dict(motor=m(), labels=np.array([0.5, 1, 2])),
        "big": dict(motor=np.full((2, 3, 1), 1e39)),
    }

    def result(fn, *args) -> str:
        try:
            return memory_digest(fn(*args))
        except UserError as exc:
            return str(exc).replace(str(tmp_path), "<d>")

    out = {}
    for name, arrays in cases.items():
        np.savez(tmp_path / f"{name}.npz", **arrays)
        out[name] = result(import_npz, tmp_path / f"{name}.npz", 9)
    root = tmp_path / "csv"
    (root / "reach").mkdir(parents=True)
    (root / "a.csv").write_text("t,q0,q1\n0,1,2\n0.5,2,3\n1,3,1\n")
    (root / "reach" / "b.csv").write_text("t,q0,q1\n0,1,2\n1,2,3\n")
    out["csv"] = result(import_csv_folder, root, 6)
    (root / "c.csv").write_text("t,q0,q1\n0,1,2\n0,2,3\n")
    out["csv clock"] = result(import_csv_folder, root, 6)
    (root / "c.csv").write_text("t,q0,q1\n0,1,2\nnan,2,3\n")
    out["csv nan clock"] = result(import_csv_folder, root, 6)
    assert out == PINNED_IMPORTS
