"""The shard layout of a generation into a file: shard sizes, directory, manifest, file settings.

With ``out``, :func:`primspace.sim.generate.generate_dataset` splits the samples into
shards of consecutive indices whose size depends on N alone (:func:`shard_ranges`); each
job writes its shard as a complete data set file into :func:`shard_dir` (``.<out
name>.shards/`` beside ``out``), whose ``manifest.json`` (:func:`shard_manifest`) names
the generation: settings, seed, layout and versions. Shards are reused by a re-run only
when the manifest is equal (:func:`prepare_shard_dir`).
"""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path
from typing import Any

from primspace.sim.config import PARAM_NAMES, PRESETS, GenerationConfig
from primspace.sim.primitives import PRIMITIVES
from primspace.sim.variation import SCENE_NAMES
from primspace.utils.errors import DataError, UserError

__all__ = [
    "MANIFEST_NAME",
    "shard_size",
    "shard_ranges",
    "shard_dir",
    "shard_path",
    "shard_manifest",
    "prepare_shard_dir",
    "failed_shards_error",
    "file_settings",
]

#: The file in a shard directory that says which generation its shards belong to.
MANIFEST_NAME = "manifest.json"


def shard_size(n_samples: int) -> int:
    """Samples per shard, from N alone (about N / 8, within 4..32).

    The layout never depends on the worker count or the backend, so the shard files of
    an interrupted run fit a re-run with any ``workers`` or ``backend``.
    """
    return max(4, min(32, math.ceil(n_samples / 8)))


def shard_ranges(n_samples: int) -> list[tuple[int, int]]:
    """``(start, stop)`` of every shard: consecutive sample indices of :func:`shard_size`."""
    size = shard_size(n_samples)
    return [(a, min(n_samples, a + size)) for a in range(0, n_samples, size)]


def shard_dir(out: str | os.PathLike) -> Path:
    """Where the shards of ``out`` are written: ``.<out name>.shards`` beside it."""
    out = Path(os.path.abspath(out))
    return out.parent / f".{out.name}.shards"


def shard_manifest(config: GenerationConfig, seed: int) -> dict[str, Any]:
    """What identifies a generation's shards: settings, seed, layout and versions (JSON)."""
    from primspace import __version__
    from primspace.data.schema import SCHEMA_VERSION

    manifest = {
        "format": "primspace generation shards",
        "primspace_version": __version__,
        "schema_version": SCHEMA_VERSION,
        "seed": int(seed),
        "config": config.to_dict(),
        "n_samples": config.n_samples,
        "shard_size": shard_size(config.n_samples),
    }
    return json.loads(json.dumps(manifest))  # as it reads back from the file


def prepare_shard_dir(directory: Path, manifest: dict, overwrite: bool) -> None:
    """Make ``directory`` ready for this generation's shards, keeping those it already holds.

    Shards of another generation (another seed, setting, layout or primspace version)
    are never reused: with ``overwrite`` they are removed, else :class:`UserError`.
    """
    from primspace.utils.files import atomic_write_json

    file = directory / MANIFEST_NAME
    try:
        found = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        found = None
    if found == manifest:
        return
    if any(directory.glob("shard-*.h5")):
        if not overwrite:
            raise UserError(
                f"{directory}: holds shards of another generation ({_differences(found, manifest)}); "
                "re-run with their settings to resume, or pass --overwrite to discard them"
            )
        shutil.rmtree(directory)
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write_json(file, manifest)


def _differences(found, manifest: dict) -> str:
    if not isinstance(found, dict):
        return "no readable manifest"
    keys = [k for k in manifest if k != "config" and found.get(k) != manifest[k]]
    old = found.get("config") if isinstance(found.get("config"), dict) else {}
    keys += [k for k in manifest["config"] if old.get(k) != manifest["config"][k]]
    return "different " + ", ".join(keys)


def shard_path(directory: Path, start: int, stop: int) -> Path:
    return directory / f"shard-{start:06d}-{stop:06d}.h5"


def failed_shards_error(failures: list, out, directory: Path, n_shards: int) -> Exception:
    """One error for every failed shard: a :class:`DataError` line, or (a bug) a RuntimeError."""
    failures = sorted(failures, key=lambda f: f[0])
    kept = n_shards - len(failures)
    resume = f"the other {kept} are kept in {directory} and a re-run skips them" if kept else "none finished"
    unexpected = [o for _, o in failures if o.error.partition(": ")[0] not in ("DataError", "UserError")]
    if unexpected:
        return RuntimeError(f"a generation job failed ({resume}): {unexpected[0].error}\n{unexpected[0].traceback}")
    reasons = [o.error.partition(": ")[2] for _, o in failures]
    listed = "; ".join(reasons[:3]) + (f"; and {len(reasons) - 3} more" if len(reasons) > 3 else "")
    return DataError(f"{listed} ({len(failures)} of {n_shards} shards failed; {resume})", path=out)


def _source(config: GenerationConfig, seed: int) -> str:
    preset = next((name for name, cfg in PRESETS.items() if cfg == config), None)
    return "primspace.sim " + json.dumps({"preset": preset, "seed": seed, "config": config.to_dict()})


def file_settings(config: GenerationConfig, seed: int, n_samples: int) -> dict[str, Any]:
    """:class:`~primspace.data.DatasetWriter` settings of a generated file of ``n_samples``."""
    return {
        "n_samples": n_samples,
        "length": config.length,
        "joint_names": _joint_names(),
        "image_size": config.image_size,
        "label_names": list(PRIMITIVES),
        "param_names": list(PARAM_NAMES),
        "dt": config.dt,
        "source": _source(config, seed),
        **({"scene_names": list(SCENE_NAMES)} if config.scene_variation != "none" else {}),
    }


def _joint_names() -> list[str]:
    from primspace.sim.scene import JOINT_NAMES

    return list(JOINT_NAMES)
