"""What the importers, ``import -T`` and the report refuse (issue 24, items 5, 6, 7, 9, 10, 11).

Every refusal is one line on stderr, exit status 2, no traceback, no output file; paths a
data set names stay inside its folder; HDF5 links to other files are not followed; a
report embeds only regular files inside the experiment folder.
"""

from __future__ import annotations

import base64
import json
import shutil

import h5py
import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from test_data_import_frames import joints_of, robomimic_demos, write_robomimic
from test_import_lerobot import edit_episodes, write_v2, write_v3

DATA_TEMPLATE = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"  # LeRobot v3.0
CAMERA = "observation.images.top"


def _import(run_cli, src, *args):
    out = src.parent / "out.h5"
    return run_cli("import", src, *args, "-T", "9", "--out", out), out


def _refused(result, out, *fragments):
    assert_user_error(result, *fragments)
    assert not out.exists()


def _edit_info(root, **changes):
    file = root / "meta" / "info.json"
    info = json.loads(file.read_text())
    info.update(changes)
    for key in [k for k, v in changes.items() if v is _DROP]:
        del info[key]
    file.write_text(json.dumps(info))


_DROP = object()


def _episodes(root, *indices):
    lines = [json.dumps({"episode_index": e, "tasks": [f"t{k}"]}) for k, e in enumerate(indices)]
    (root / "meta" / "episodes.jsonl").write_text("\n".join(lines) + "\n")


# ------------------------------------------------------------------- LeRobot: containment


@pytest.fixture
def lerobot(tmp_path):
    """A LeRobot v3.0 data set: two episodes in one data file and one video."""
    root = tmp_path / "sets" / "ds"
    write_v3(root, lengths=(8, 6), tasks=("a", "b"), data_files=((0, 0),) * 2, video_files=((0, 0),) * 2)
    return root


@pytest.fixture
def lerobot_v2(tmp_path):
    root = tmp_path / "sets" / "v2"
    write_v2(root, lengths=(8, 6), tasks=("a", "b"))
    return root


def test_lerobot_absolute_data_path_is_refused(run_cli, lerobot, tmp_path):
    shutil.copytree(lerobot / "data", tmp_path / "outside" / "data")  # a readable copy elsewhere
    template = str(tmp_path / "outside" / DATA_TEMPLATE)
    _edit_info(lerobot, data_path=template)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'data_path'", template, "absolute")


def test_lerobot_data_path_escaping_with_dotdot_is_refused(run_cli, lerobot):
    shutil.copytree(lerobot / "data", lerobot.parent / "stolen" / "data")
    _edit_info(lerobot, data_path="../stolen/" + DATA_TEMPLATE)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'data_path'", "../stolen/", "outside")


def test_lerobot_symlinked_chunk_folder_pointing_outside_is_refused(run_cli, lerobot, tmp_path):
    shutil.move(lerobot / "data", tmp_path / "elsewhere")
    (lerobot / "data").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'data_path'", "outside")


def test_lerobot_video_path_escaping_is_refused(run_cli, lerobot):
    shutil.copytree(lerobot / "videos", lerobot.parent / "v" / "videos")
    _edit_info(lerobot, video_path="../v/videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4")
    _refused(*_import(run_cli, lerobot, "--images", CAMERA), "meta/info.json", "field 'video_path'", "../v/videos")


def test_lerobot_templates_inside_the_folder_still_import(run_cli, lerobot):
    res, out = _import(run_cli, lerobot, "--images", CAMERA, "--image-size", "8x8")
    assert res.code == 0, res.err
    assert MotionDataset.load(out).images.shape == (2, 9, 8, 8, 3)


@pytest.mark.parametrize(
    "template, fragment",
    [
        ("data/{file_index.__class__}.parquet", "{file_index.__class__}"),  # used to expand
        ("data/{file_index.foo}.parquet", "{file_index.foo}"),  # used to be a traceback
        ("data/{file_index[0]}.parquet", "{file_index[0]}"),  # used to be a traceback
        ("data/{file_index!r}.parquet", "{file_index!r}"),  # used to be accepted
        ("data/{file_index:>8}.parquet", "{file_index:>8}"),
        ("data/{file_index:0999999999d}.parquet", "{file_index:0999999999d}"),  # a 1 GB file name
        ("data/{0}.parquet", "{0}"),
        ("data/{}.parquet", "{}"),
        ("data/{video_key}/e.parquet", "{video_key}"),  # not a field of data_path
        ("data/{episode_index:06d}.parquet", "{episode_index:06d}; a v3 template may use only {chunk_index}"),  # v2's
        ("data/{file_index:03d", "data/{file_index:03d"),  # unbalanced
    ],
)
def test_lerobot_template_fields_are_plain_integers(run_cli, lerobot, template, fragment):
    _edit_info(lerobot, data_path=template)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'data_path'", fragment)


def test_lerobot_v2_template_fields_are_its_own(run_cli, lerobot_v2):
    _edit_info(lerobot_v2, data_path=DATA_TEMPLATE)
    _refused(
        *_import(run_cli, lerobot_v2),
        "meta/info.json",
        "field 'data_path'",
        "{chunk_index:03d}; a v2 template may use only {episode_chunk}, {episode_index}",
    )
    _edit_info(lerobot_v2, data_path="../" + "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet")
    _refused(*_import(run_cli, lerobot_v2), "meta/info.json", "field 'data_path'", "outside")


def test_lerobot_episode_tables_linked_from_outside_are_refused(run_cli, lerobot, tmp_path):
    folder = lerobot / "meta" / "episodes" / "chunk-000"
    shutil.move(folder, tmp_path / "elsewhere")
    folder.symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    _refused(*_import(run_cli, lerobot), "file-000.parquet", "field 'episodes'", "outside the data set folder")


def test_lerobot_template_that_is_not_a_string_is_refused(run_cli, lerobot):
    _edit_info(lerobot, data_path=5)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'data_path'", "must be a string")


# -------------------------------------------------------------- LeRobot: episodes, fps, chunks


def test_lerobot_duplicate_episode_index_is_refused(run_cli, lerobot, lerobot_v2):
    _episodes(lerobot_v2, 0, 1, 0)
    _refused(*_import(run_cli, lerobot_v2), "episodes.jsonl", "line 3", "episode_index 0", "line 1")
    edit_episodes(lerobot, "episode_index", {1: 0})
    _refused(
        *_import(run_cli, lerobot),
        "meta/episodes/chunk-000/file-000.parquet",
        "field 'episode_index'",
        "episode_index 0 is listed twice (also in this file)",
    )


@pytest.mark.parametrize("value", [1.7, "1", True, -1, None])
def test_lerobot_episode_index_must_be_an_integer(run_cli, lerobot_v2, value):
    _episodes(lerobot_v2, 0, value)
    _refused(*_import(run_cli, lerobot_v2), "episodes.jsonl", "line 2", "episode_index", json.dumps(value))


@pytest.mark.parametrize(
    "column, value, fragment",
    [
        ("episode_index", 1.5, "row 0: episode_index 0.0 is not a whole number >= 0"),  # the column becomes floats
        ("episode_index", -1, "row 1: episode_index -1 is not a whole number >= 0"),
        ("data/file_index", None, "row 1: data/file_index null is not a whole number >= 0"),
        ("dataset_to_index", 8, "row 1: dataset_to_index 8 does not come after dataset_from_index 8"),
        (f"videos/{CAMERA}/from_timestamp", float("nan"), "from_timestamp NaN is not a time in seconds >= 0"),
        (f"videos/{CAMERA}/to_timestamp", 0.8, "to_timestamp 0.8 does not come after"),
    ],
)
def test_lerobot_v3_episode_rows_are_checked(run_cli, lerobot, column, value, fragment):
    edit_episodes(lerobot, column, {1: value})
    _refused(
        *_import(run_cli, lerobot, "--images", CAMERA),
        "meta/episodes/chunk-000/file-000.parquet",
        f"field '{column}'",
        fragment,
    )


@pytest.mark.parametrize("fps", ["fast", 0, float("nan"), float("inf"), -10, True, [10], 1e-320, 1e12])
def test_lerobot_fps_must_be_a_positive_finite_rate(run_cli, lerobot, fps):
    _edit_info(lerobot, fps=fps)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'fps'", json.dumps(fps))


def test_lerobot_missing_fps_is_refused(run_cli, lerobot):
    _edit_info(lerobot, fps=_DROP)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'fps'", "missing")


@pytest.mark.parametrize("chunks", ["abc", [1], 0.5, 0, -2, True])
def test_lerobot_chunks_size_must_be_a_positive_integer(run_cli, lerobot, chunks):
    _edit_info(lerobot, chunks_size=chunks)
    _refused(*_import(run_cli, lerobot), "meta/info.json", "field 'chunks_size'", json.dumps(chunks))


# ------------------------------------------------------------------------------ robomimic


@pytest.fixture
def lift(tmp_path):
    path = tmp_path / "lift.hdf5"
    write_robomimic(path, robomimic_demos((12, 14)))
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["secret"] = np.full((14, 7), 42.0)
        f["images"] = np.zeros((14, 32, 40, 3), np.uint8)
        group = f.create_group("demo/obs")
        group["robot0_joint_pos"] = np.full((14, 7), 42.0)
    return path


_JOINTS = ("--joints", "robot0_joint_pos")


def _replace(path, name, link):
    with h5py.File(path, "a") as f:
        del f[name]
        f[name] = link


def test_robomimic_external_link_to_a_dataset_is_refused(run_cli, lift, tmp_path):
    _replace(lift, "data/demo_1/obs/robot0_joint_pos", h5py.ExternalLink(str(tmp_path / "other.h5"), "/secret"))
    _refused(
        *_import(run_cli, lift, *_JOINTS), "lift.hdf5", "data/demo_1/obs/robot0_joint_pos", "external link", "other.h5"
    )


def test_robomimic_external_link_to_a_demo_group_is_refused(run_cli, lift, tmp_path):
    _replace(lift, "data/demo_1", h5py.ExternalLink(str(tmp_path / "other.h5"), "/demo"))
    _refused(*_import(run_cli, lift, *_JOINTS), "lift.hdf5", "data/demo_1", "external link")


def test_robomimic_external_link_to_frames_is_refused(run_cli, lift, tmp_path):
    _replace(lift, "data/demo_1/obs/agentview_image", h5py.ExternalLink(str(tmp_path / "other.h5"), "/images"))
    _refused(
        *_import(run_cli, lift, *_JOINTS, "--images", "agentview_image"),
        "lift.hdf5",
        "data/demo_1/obs/agentview_image",
        "external link",
    )


def test_robomimic_dataset_stored_in_another_file_is_refused(run_cli, lift, tmp_path):
    raw = tmp_path / "raw.bin"
    np.full((14, 7), 42.0).tofile(raw)
    with h5py.File(lift, "a") as f:
        del f["data/demo_1/obs/robot0_joint_pos"]
        f["data/demo_1/obs"].create_dataset("robot0_joint_pos", (14, 7), "f8", external=[(str(raw), 0, 14 * 7 * 8)])
    _refused(*_import(run_cli, lift, *_JOINTS), "lift.hdf5", "data/demo_1/obs/robot0_joint_pos", "raw.bin")


def test_robomimic_virtual_dataset_is_refused(run_cli, lift, tmp_path):
    layout = h5py.VirtualLayout((14, 7), "f8")
    layout[:] = h5py.VirtualSource(str(tmp_path / "other.h5"), "secret", shape=(14, 7))
    with h5py.File(lift, "a") as f:
        del f["data/demo_1/obs/robot0_joint_pos"]
        f["data/demo_1/obs"].create_virtual_dataset("robot0_joint_pos", layout)
    _refused(*_import(run_cli, lift, *_JOINTS), "lift.hdf5", "data/demo_1/obs/robot0_joint_pos", "virtual")


def test_robomimic_soft_link_out_of_the_demo_is_refused_one_inside_is_read(run_cli, lift):
    with h5py.File(lift, "a") as f:
        for demo in ("demo_0", "demo_1"):  # inside the demo: fine
            f[f"data/{demo}/obs/q"] = h5py.SoftLink(f"/data/{demo}/obs/robot0_joint_pos")
    res, out = _import(run_cli, lift, "--joints", "q")
    assert res.code == 0, res.err
    out.unlink()
    _replace(lift, "data/demo_1/obs/robot0_joint_pos", h5py.SoftLink("/data/demo_0/obs/robot0_joint_pos"))
    _refused(
        *_import(run_cli, lift, *_JOINTS),
        "lift.hdf5",
        "data/demo_1/obs/robot0_joint_pos",
        "soft link",
        "/data/demo_0/obs/robot0_joint_pos",
    )


def test_robomimic_demo_names_with_the_same_number_are_refused(run_cli, tmp_path):
    path = tmp_path / "d.hdf5"
    write_robomimic(path, robomimic_demos((12, 14, 10), names=["demo_0", "demo_1", "demo_01"]))
    _refused(*_import(run_cli, path, *_JOINTS), "d.hdf5", "demo_01", "demo_1", "same number")


@pytest.mark.parametrize("images", [(), ("--images", "agentview_image")])
def test_robomimic_empty_demo_is_called_empty(run_cli, lift, images):
    with h5py.File(lift, "a") as f:
        for key, shape in (("robot0_joint_pos", (0, 7)), ("agentview_image", (0, 32, 40, 3))):
            del f[f"data/demo_1/obs/{key}"]
            f[f"data/demo_1/obs/{key}"] = np.zeros(shape, np.uint8 if len(shape) == 4 else float)
    res, out = _import(run_cli, lift, *_JOINTS, *images)
    _refused(res, out, "lift.hdf5", "sample 1", "data/demo_1/obs/robot0_joint_pos", "empty")
    assert "truncated" not in res.err


@pytest.mark.parametrize("freq", [1e-320, 0, -20, float("nan"), float("inf"), "fast", 1e12])
def test_robomimic_control_freq_must_give_a_sensible_dt(run_cli, tmp_path, freq):
    path = tmp_path / "d.hdf5"
    write_robomimic(path, robomimic_demos((12, 14)), control_freq=freq)
    _refused(*_import(run_cli, path, *_JOINTS), "d.hdf5", "control_freq", json.dumps(freq))


def test_robomimic_without_control_freq_still_imports(run_cli, tmp_path):
    path = tmp_path / "d.hdf5"
    write_robomimic(path, robomimic_demos((12, 14)), control_freq=None)
    res, _ = _import(run_cli, path, *_JOINTS)
    assert res.code == 0, res.err


# ------------------------------------------------------------------------------------ npz


def test_text_file_named_npz_is_not_an_archive(run_cli, tmp_path):
    (tmp_path / "f.npz").write_text("motor\n1,2,3\n")
    res, out = _import(run_cli, tmp_path / "f.npz")
    _refused(res, out, "f.npz", "it is not a zip file (an npz archive is a zip file of .npy arrays")
    assert "pickle" not in res.err


def test_npy_file_named_npz_is_not_an_archive(run_cli, tmp_path):
    with open(tmp_path / "f.npz", "wb") as fh:
        np.save(fh, np.zeros((2, 5, 1)))
    _refused(*_import(run_cli, tmp_path / "f.npz"), "f.npz", "a single .npy array, not a zip file")


# ----------------------------------------------------------------------------------- -T


@pytest.mark.parametrize("length", ["100000000000", "1" + "0" * 30, "1e30", "100001", "2.5", "abc"])
def test_length_is_bounded_and_one_line(run_cli, tmp_path, length):
    np.savez(tmp_path / "f.npz", motor=np.zeros((2, 5, 1)))
    out = tmp_path / "o.h5"
    res = run_cli("import", tmp_path / "f.npz", "-T", length, "--out", out)
    _refused(res, out, "--length", length, "100,000")


def test_length_at_the_bound_is_accepted(run_cli, tmp_path):
    np.savez(tmp_path / "f.npz", motor=joints_of(5, 1, 0.0)[None])
    res = run_cli("import", tmp_path / "f.npz", "-T", "100000", "--out", tmp_path / "o.h5")
    assert res.code == 0, res.err
    assert MotionDataset.load(tmp_path / "o.h5").length == 100_000


def test_length_help_states_the_bound(run_cli):
    res = run_cli("import", "--help")
    assert "100,000" in " ".join(res.out.split())


# --------------------------------------------------------------------------------- report

SECRET = b"SECRET-HOSTNAME-0123456789"


def _experiment(tmp_path):
    exp = tmp_path / "exp"
    (exp / "figures").mkdir(parents=True)
    (exp / "experiment.json").write_text(json.dumps({"preset": "x"}))
    secret = tmp_path / "hostname"
    secret.write_bytes(SECRET)
    return exp, secret


def _leaked(html: str) -> bool:
    return base64.b64encode(SECRET).decode()[:24] in html


def test_report_does_not_embed_what_a_symlinked_figure_points_to(run_cli, tmp_path):
    exp, secret = _experiment(tmp_path)
    (exp / "figures" / "latent_pca_x.png").symlink_to(secret)
    res = run_cli("report", exp)
    assert res.code == 0, res.err
    html = (exp / "report.html").read_text()
    assert not _leaked(html)
    assert "latent_pca_x.png" in html and "symbolic link" in html  # a visible note instead


def test_report_does_not_embed_files_of_a_symlinked_figures_folder(run_cli, tmp_path):
    exp, secret = _experiment(tmp_path)
    (tmp_path / "private").mkdir()
    shutil.copy(secret, tmp_path / "private" / "latent_pca_y.png")
    (exp / "figures").rmdir()
    (exp / "figures").symlink_to(tmp_path / "private", target_is_directory=True)
    res = run_cli("report", exp)
    assert res.code == 0, res.err
    html = (exp / "report.html").read_text()
    assert not _leaked(html) and "outside the experiment folder" in html


def test_report_still_embeds_regular_figures(run_cli, tmp_path):
    exp, _ = _experiment(tmp_path)
    (exp / "figures" / "latent_pca_z.png").write_bytes(SECRET)  # a regular file inside: embedded
    assert run_cli("report", exp).code == 0
    assert _leaked((exp / "report.html").read_text())


def test_html_report_figure_refuses_symlinks_without_a_root(tmp_path):
    from primspace.report.page import HtmlReport

    _, secret = _experiment(tmp_path)
    (tmp_path / "x.png").symlink_to(secret)
    report = HtmlReport("t")
    report.figure(tmp_path / "x.png")
    assert not _leaked(report.render()) and "symbolic link" in report.render()


# ------------------------------------------------- found by tests/test_import_fuzz.py and its review


def test_robomimic_dataset_declaring_more_than_memory_is_refused(run_cli, tmp_path):
    """A 5 KB file can declare a 50 TiB array (HDF5 stores no chunk that was never written)."""
    path = tmp_path / "big.hdf5"
    with h5py.File(path, "w") as f:
        f.create_dataset("data/demo_0/obs/q", shape=(10**12, 7), chunks=(1000, 7), dtype="f8")
    _refused(
        *_import(run_cli, path, "--joints", "q"),
        "big.hdf5",
        "field 'q'",
        "sample 0",
        "GiB",
        "more than half this machine's memory",
    )


def test_npz_header_declaring_more_than_memory_is_refused(run_cli, tmp_path):
    import io
    import zipfile

    from numpy.lib import format as npy

    buffer = io.BytesIO()
    npy.write_array_header_1_0(buffer, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 3)})
    buffer.write(np.zeros(30).tobytes())
    with zipfile.ZipFile(tmp_path / "f.npz", "w") as z:
        z.writestr("motor.npy", buffer.getvalue())
    _refused(*_import(run_cli, tmp_path / "f.npz"), "f.npz", "field 'motor'", "too large to read into memory")


@pytest.mark.parametrize("method", ["ZIP_DEFLATED", "ZIP_STORED"])
def test_npz_damaged_member_names_the_member(run_cli, tmp_path, method):
    """Damaged deflate data (zlib.error) and an unknown compression method used to be tracebacks."""
    import zipfile

    np.savez_compressed(tmp_path / "f.npz", motor=joints_of(50, 2, 0.0)[None])
    data = bytearray((tmp_path / "f.npz").read_bytes())
    if method == "ZIP_DEFLATED":
        start = data.index(b"motor.npy") + len("motor.npy")
        data[start + 40 : start + 60] = bytes(20)  # inside the compressed stream
    else:
        data[8] = 99  # the local header's compression method
        central = data.rindex(b"PK\x01\x02")
        data[central + 10] = 99
    (tmp_path / "f.npz").write_bytes(bytes(data))
    assert zipfile.is_zipfile(tmp_path / "f.npz")
    _refused(*_import(run_cli, tmp_path / "f.npz"), "f.npz")


def test_names_with_a_newline_keep_the_message_on_one_line(run_cli, tmp_path):
    import zipfile

    with zipfile.ZipFile(tmp_path / "f.npz", "w") as z:
        z.writestr("odd\nname.npy", b"not an array")
    _refused(*_import(run_cli, tmp_path / "f.npz"), "f.npz", "odd\\nname")
    path = tmp_path / "d.hdf5"
    write_robomimic(path, robomimic_demos((6, 7)))
    with h5py.File(path, "a") as f:
        f["data/demo_0/obs/bad\nkey"] = np.zeros(6)
    _refused(*_import(run_cli, path, "--joints", "nope"), "d.hdf5", "bad\\nkey")


def test_lerobot_damaged_column_name_is_one_line(run_cli, lerobot):
    """A parquet column name that is not UTF-8 used to escape as a UnicodeDecodeError."""
    file = lerobot / "data" / "chunk-000" / "file-000.parquet"
    data = file.read_bytes()
    at = data.index(b"observation.state")  # the column chunk's path in the schema
    file.write_bytes(data[:at] + b"\xd5" + data[at + 1 :])
    _refused(*_import(run_cli, lerobot), "file-000.parquet", "sample 0")


def test_robomimic_soft_link_through_an_external_link_is_refused(run_cli, lift, tmp_path):
    """A soft link that stays inside its demo by name but passes through an external link."""
    with h5py.File(lift, "a") as f:
        f["data/demo_1/ext"] = h5py.ExternalLink(str(tmp_path / "other.h5"), "/")
        del f["data/demo_1/obs/robot0_joint_pos"]
        f["data/demo_1/obs/robot0_joint_pos"] = h5py.SoftLink("/data/demo_1/ext/secret")
    _refused(*_import(run_cli, lift, *_JOINTS), "lift.hdf5", "data/demo_1/ext", "external link")


def test_robomimic_soft_link_loop_is_refused(run_cli, lift):
    with h5py.File(lift, "a") as f:
        f["data/demo_1/obs/a"] = h5py.SoftLink("/data/demo_1/obs/b")
        f["data/demo_1/obs/b"] = h5py.SoftLink("/data/demo_1/obs/a")
        del f["data/demo_1/obs/robot0_joint_pos"]
        f["data/demo_1/obs/robot0_joint_pos"] = h5py.SoftLink("a")  # relative to obs
    _refused(*_import(run_cli, lift, *_JOINTS), "lift.hdf5", "sample 1")
