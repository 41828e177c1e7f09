"""``primspace import``: demonstrations from other formats into a data set file.

The options are module constants so the command's signature stays readable; each says
which formats take it, and :func:`_check_import_options` refuses it for the others.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from primspace.cli.app import app
from primspace.cli.options import name_list
from primspace.utils.errors import UserError


class ImportFormat(str, Enum):
    npz = "npz"
    npy = "npy"
    csv = "csv"
    lasa = "lasa"
    ts = "ts"
    robomimic = "robomimic"
    lerobot = "lerobot"


class ImageFit(str, Enum):
    crop = "crop"
    pad = "pad"
    stretch = "stretch"


_FRAME_FORMATS = ("robomimic", "lerobot")  # formats that take --joints and --images
_PADDED_FORMATS = ("npz", "npy")  # formats whose stacked arrays may be padded (--keep-padding)
#: The most steps ``import -T`` resamples to: 100 s at 1 kHz. The arrays grow with T (N x T x J
#: float64 while resampling, N x T x H x W x 3 bytes of frames), so a larger T is a typo that
#: would end in a memory error, not a data set.
MAX_LENGTH = 100_000
#: The largest side of stored frames, ``--image-size``: a 1024x1024 frame is 3 MiB, so T of them
#: per sample are already more than the decoder's head is meant for; a larger size is a typo
#: that would end in a memory error (80000x80000 asked for 179 GiB), not a data set.
MAX_IMAGE_SIDE = 1024
# the mark this command writes into its outputs (primspace.utils.outputs): --overwrite replaces only its own
_IMPORT_MARK = "primspace import"

_SRC = typer.Argument(
    None,
    help="A .npz file, a folder of .npy arrays, a folder of CSV files, a robomimic .hdf5 file, a LeRobot "
    "data set folder (v3.0 or v2.x), or nothing / 'lasa' for --format lasa; --format ts: one or more UEA/UCR "
    ".ts files (e.g. X_TRAIN.ts X_TEST.ts) or a folder of them.",
)
_FORMAT = typer.Option(None, "--format", "-f", help="Input format; guessed from SRC when omitted.")
_LENGTH = typer.Option(
    ...,
    "--length",
    "-T",
    metavar="T",
    help=f"Resample every sequence to T steps, 2 to {MAX_LENGTH:,} (memory grows "
    "with T: N x T x J x 8 bytes, and N x T x H x W x 3 with frames; 100,000 steps are 100 s at 1 kHz).",
)
_OUT = typer.Option(..., "--out", "-o", help="The HDF5 data set to write.")
_JOINTS = typer.Option(
    None,
    "--joints",
    help="robomimic: keys, comma-separated, concatenated in this order (required): obs keys, or "
    "demo-level ones such as actions or states; lerobot: state features (default observation.state).",
)
_IMAGES = typer.Option(
    None,
    "--images",
    help="robomimic: the obs key of the frames (e.g. agentview_image); lerobot: the camera "
    "feature (e.g. observation.images.top). npz and npy: frames are read from 'images'.",
)
_IMAGE_SIZE = typer.Option(
    None,
    "--image-size",
    help=f"HxW of the stored frames (default 48x64, each side at most {MAX_IMAGE_SIDE}): resized with an "
    "anti-aliasing filter.",
)
_IMAGE_FIT = typer.Option(
    ImageFit.crop,
    "--image-fit",
    help="A frame of another aspect ratio: crop (centre crop, keeps the aspect "
    "ratio), pad (black bars, keeps the whole scene) or stretch (distorts).",
)
_EPISODES = typer.Option(None, "--episodes", help="lerobot: the episodes to import, e.g. 0,3,10-20 (default all).")
_FILTER_KEY = typer.Option(
    None, "--filter-key", help="robomimic: import only the demos that mask/<KEY> names (a split such as train)."
)
_KEEP_PADDING = typer.Option(
    False,
    "--keep-padding",
    help="npz and npy: keep trailing steps that repeat the last value exactly (by default "
    "they are taken as padding when no lengths are given).",
)
_SHAPES = typer.Option(None, help="lasa: comma-separated shape names (default: 26 single-pattern shapes).")
_VELOCITIES = typer.Option(False, help="lasa: add velocities vx, vy as joints.")
_OVERWRITE = typer.Option(False, help="Replace OUT if it is an earlier import output (nothing else).")


@app.command("import")
def import_command(
    src: list[Path] | None = _SRC,
    format: ImportFormat | None = _FORMAT,
    length: str = _LENGTH,
    out: str = _OUT,
    joints: str | None = _JOINTS,
    images: str | None = _IMAGES,
    image_size: str | None = _IMAGE_SIZE,
    image_fit: ImageFit = _IMAGE_FIT,
    episodes: str | None = _EPISODES,
    filter_key: str | None = _FILTER_KEY,
    keep_padding: bool = _KEEP_PADDING,
    shapes: str | None = _SHAPES,
    velocities: bool = _VELOCITIES,
    overwrite: bool = _OVERWRITE,
) -> None:
    """Import demonstrations (npz, npy folder, CSV folder, LASA, UEA/UCR .ts, robomimic HDF5, LeRobot) into a MotionDataset file.

    Frames: each step takes the recorded frame nearest in time, fitted (--image-fit) and resized to --image-size.
    """
    from primspace.utils.outputs import output_file

    length = _parse_length(length)
    sources = list(src or [])
    src = sources[0] if sources else None
    inputs = tuple(s for s in sources if str(s).lower() != "lasa")
    out = output_file(out, inputs=inputs or (None,), overwrite=overwrite, writer=_IMPORT_MARK)
    fmt = format.value if format is not None else _guess_format(src)
    if len(sources) > 1 and fmt != "ts":
        raise UserError(f"--format {fmt} reads one source, got {len(sources)}; several files are read by --format ts")
    options = {
        "joints": joints,
        "images": images,
        "image_size": image_size,
        "episodes": episodes,
        "filter_key": filter_key,
        "keep_padding": keep_padding,
        "image_fit": image_fit.value,
    }
    _check_import_options(fmt, options)
    if fmt == "lasa":
        from primspace.data.importers import import_lasa

        names = [s.strip() for s in shapes.split(",") if s.strip()] if shapes else None
        ds = import_lasa(length, shapes=names, velocities=velocities)
    elif src is None:
        raise UserError(f"--format {fmt} needs a source path")
    elif fmt == "ts":
        from primspace.data.importers import import_ts

        ds = import_ts(sources, length)
    else:
        ds = _import_file(fmt, src, length, options)
    ds.save(out, overwrite=overwrite, writer=_IMPORT_MARK)
    frames = f", frames {ds.image_size[0]}x{ds.image_size[1]}" if ds.has_images else ""
    typer.echo(f"wrote {out}: {len(ds)} samples x {ds.length} steps x {ds.n_joints} joints{frames}")


def _import_file(fmt: str, src: Path, length: int, options: dict):
    """Run the importer of ``fmt`` on ``src`` with the command's ``options``."""
    from primspace.data import importers

    size = _parse_image_size(options["image_size"])
    frames = {"image_size": size, "image_fit": options["image_fit"]}
    if fmt == "npz":
        return importers.import_npz(src, length, **frames, keep_padding=options["keep_padding"])
    if fmt == "npy":
        return importers.import_npy_folder(src, length, **frames, keep_padding=options["keep_padding"])
    if fmt == "csv":
        return importers.import_csv_folder(src, length)
    keys = name_list(options["joints"], "--joints") if options["joints"] is not None else None
    if fmt == "robomimic":
        return importers.import_robomimic(
            src, length, joints=keys or (), images=options["images"], **frames, filter_key=options["filter_key"]
        )
    episodes = None if options["episodes"] is None else importers.parse_episodes(options["episodes"])
    return importers.import_lerobot(
        src, length, joints=keys or ("observation.state",), images=options["images"], **frames, episodes=episodes
    )


#: The formats each option applies to (``--image-size`` and ``--image-fit`` also need frames).
_OPTION_FORMATS = {
    "joints": _FRAME_FORMATS,
    "images": _FRAME_FORMATS,
    "episodes": ("lerobot",),
    "filter_key": ("robomimic",),
    "keep_padding": _PADDED_FORMATS,
}


def _check_import_options(fmt: str, options: dict) -> None:
    """Refuse flags the format does not take (one line naming the flag)."""
    for name, formats in _OPTION_FORMATS.items():
        if options[name] not in (None, False) and fmt not in formats:
            flag = "--" + name.replace("_", "-")
            raise UserError(f"{flag} applies to --format {' or '.join(formats)}, not {fmt}")
    no_frames = fmt in ("csv", "lasa", "ts") or (fmt in _FRAME_FORMATS and not options["images"])
    for flag, value, default in (
        ("--image-size", options["image_size"], None),
        ("--image-fit", options["image_fit"], "crop"),
    ):
        if value != default and no_frames:
            raise UserError(
                f"{flag} {value}: there are no frames to resize (--format {fmt}"
                f"{' without --images' if fmt in _FRAME_FORMATS else ''})"
            )


def _parse_length(text: str) -> int:
    """``-T``: a whole number of steps from 2 to :data:`MAX_LENGTH` (one line otherwise)."""
    value = text.strip()
    if not (value.isascii() and value.isdigit()):  # "1e30", "2.5", "-3", "²": not a count of steps
        raise UserError(f"--length {text}: must be a whole number of steps from 2 to {MAX_LENGTH:,}")
    if len(value) > 9 or int(value) > MAX_LENGTH:
        raise UserError(
            f"--length {text}: at most {MAX_LENGTH:,} steps (100 s at 1 kHz); the arrays grow with T "
            "(N x T x J x 8 bytes, N x T x H x W x 3 with frames), a longer T is a typo that would "
            "run out of memory"
        )
    if int(value) < 2:
        raise UserError(f"--length {text}: must be at least 2 steps (a first and a last)")
    return int(value)


def _parse_image_size(text: str | None) -> tuple[int, int]:
    """``"48x64"`` -> ``(48, 64)``, a size the decoder's image head can produce."""
    from primspace.data.importers import DEFAULT_IMAGE_SIZE
    from primspace.model.config import ModelConfig, check_image_size

    if text is None:
        return DEFAULT_IMAGE_SIZE
    parts = text.lower().replace(" ", "").split("x")
    if len(parts) != 2 or not all(p.isdigit() and int(p) > 0 for p in parts):
        raise UserError(f"--image-size must be HxW in pixels, e.g. 48x64; got '{text}'")
    size = (int(parts[0]), int(parts[1]))
    if max(size) > MAX_IMAGE_SIDE:
        raise UserError(f"--image-size {text}: each side at most {MAX_IMAGE_SIDE} pixels")
    try:
        check_image_size(size, ModelConfig().image_channels)
    except UserError as exc:
        raise UserError(f"--image-size {text}: {exc}") from None
    return size


def _guess_format(src: Path | None) -> str:
    """The format of ``src``; an HDF5 file is robomimic only when it is a ``.hdf5`` file with
    ``data/demo_N`` groups (a ``.h5`` file is usually a primspace data set already)."""
    if src is None or str(src).lower() == "lasa":
        return "lasa"
    if src.is_dir():
        from primspace.data.importers import is_lerobot_dir, looks_like_npy_folder

        if is_lerobot_dir(src):
            return "lerobot"
        if looks_like_npy_folder(src):
            return "npy"
        return "ts" if any(src.glob("*.ts")) and not any(src.rglob("*.csv")) else "csv"
    suffix = src.suffix.lower()
    if suffix == ".npz":
        return "npz"
    if suffix == ".ts":
        return "ts"
    if suffix == ".hdf5":
        from primspace.data.importers import looks_like_robomimic

        if not src.exists() or looks_like_robomimic(src):
            return "robomimic"
        raise UserError(f"{src}: cannot tell the format (an HDF5 file without data/demo_N groups); pass --format")
    if suffix == ".h5":
        raise UserError(
            f"{src}: cannot tell the format of a .h5 file (usually a primspace data set, which needs no import); "
            "pass --format robomimic for a robomimic-style file"
        )
    raise UserError(f"{src}: cannot tell the format; pass --format npz|npy|csv|lasa|ts|robomimic|lerobot")
