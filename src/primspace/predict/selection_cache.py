"""Where a predictor chosen by held-out evidence is kept: one small JSON file per choice in the run folder.

:class:`~primspace.predict.selection.SelectedPredictor` chooses among its candidates by K-fold
prediction of the fitted demonstrations; the choice depends on the fitted data, the task (the
observation rule, the primitive given or not), the settings and the code that predicts. Its
:func:`choice_key` hashes all of these; the choice is kept as ``RUN/selection/<key>.json``
(:func:`choice_path`), so a later call with the same key reads the choice and the chosen
predictor's own settings instead of scoring the candidates again.

The file is written atomically (a temporary file, then a rename) and says who wrote it
(``"writer": "primspace fit-predictor"``): a file at that path that does not say so is never
replaced, and one whose recorded key differs from the key asked (a stale file) is ignored and
written again. A run folder that cannot be written keeps no choice (the prediction is made all
the same).

The prior's decoded draws (most of what fitting the chosen prior costs) are kept beside the choices
(:func:`decoded_draws`): ``RUN/selection/draws-<key>.npz``, keyed by the codes drawn and the decoder's
weights, read back as they were written (the same numbers), under the same rules.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from primspace.utils.errors import UserError
from primspace.utils.files import atomic_path, atomic_write_json
from primspace.utils.outputs import file_writer

__all__ = [
    "SELECTION_MARK",
    "SELECTION_DIR",
    "SELECTION_VERSION",
    "choice_key",
    "choice_path",
    "load_choice",
    "save_choice",
]

#: The mark of a kept choice (``writer``): ``primspace predict`` and ``primspace fit-predictor`` write it.
SELECTION_MARK = "primspace fit-predictor"
#: The folder of a run that holds its kept choices.
SELECTION_DIR = "selection"
#: The version of the selection protocol and of the candidates' numbers: part of every key, raised when
#: a change of the code would change a choice or a candidate's prediction.
SELECTION_VERSION = 2


def _digest(*arrays) -> str:
    """A hash of the arrays' dtypes, shapes and bytes (None hashed as such)."""
    h = hashlib.sha256()
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def choice_key(fitted: tuple, codes, task: dict, settings: dict) -> str:
    """The key of a choice: a hash of the fitted data (``fitted``: the scaled motor, labels and
    valid lengths the candidates are fitted on), the run's fitted ``codes``, the ``task`` and the
    ``settings`` (JSON-able dicts), primspace's version and :data:`SELECTION_VERSION`."""
    from primspace import __version__

    text = json.dumps(
        {"task": task, "settings": settings, "version": __version__, "selection": SELECTION_VERSION},
        sort_keys=True,
        default=str,
    )
    return hashlib.sha256(f"{_digest(*fitted, codes)}|{text}".encode()).hexdigest()


def choice_path(run_dir, key: str) -> Path:
    """The file of the choice of ``key`` in the run folder ``run_dir``."""
    return Path(run_dir) / SELECTION_DIR / f"{key[:20]}.json"


def load_choice(path: Path, key: str) -> dict | None:
    """The choice kept at ``path`` for ``key``, or None: no file, not ours, unreadable, or a stale key."""
    if file_writer(path) != SELECTION_MARK:
        return None
    try:
        content = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if content.get("key") != key or not isinstance(content.get("selection"), dict):
        return None
    return content


def save_choice(path: Path, key: str, record: dict) -> bool:
    """Keep ``record`` (the selection, the chosen predictor's settings) at ``path`` for ``key``,
    atomically; False (nothing written) when a file there was not written by a choice, or the
    run folder cannot be written."""
    if path.exists() and file_writer(path) != SELECTION_MARK:
        return False
    try:
        atomic_write_json(path, {"writer": SELECTION_MARK, "key": key, **record})
    except (OSError, UserError):
        return False
    return True


def _decoder_digest(run) -> str:
    """A hash of the run's decoder weights."""
    state = run.model.state_dict()
    return _digest(*(state[name].detach().cpu().numpy() for name in sorted(state)))


def _read_draws(path: Path, key: str) -> tuple[bool, np.ndarray | None]:
    """(whether ``path`` is a file of kept draws or absent, its decoded motions for ``key`` or None)."""
    if not path.exists():
        return True, None
    try:
        with np.load(path, allow_pickle=False) as kept:
            if str(kept["writer"]) != SELECTION_MARK:
                return False, None
            return True, (kept["decoded"] if str(kept["key"]) == key else None)
    except (OSError, ValueError, KeyError):
        return False, None


def decoded_draws(folder, run, codes: np.ndarray, decode) -> np.ndarray:
    """``decode(codes)`` (the prior's draws through ``run``'s decoder), kept in ``folder``: read back when
    a file there holds the draws of the same ``codes`` and decoder weights, else decoded and written
    (atomically; never over a file it did not write, and not at all where ``folder`` cannot be written)."""
    key = hashlib.sha256(f"{_digest(codes)}|{_decoder_digest(run)}".encode()).hexdigest()
    path = Path(folder) / f"draws-{key[:20]}.npz"
    ours, decoded = _read_draws(path, key)
    if decoded is not None:
        return decoded
    decoded = decode(codes)
    if ours:
        try:
            with atomic_path(path) as tmp, open(tmp, "wb") as f:
                np.savez(f, writer=np.array(SELECTION_MARK), key=np.array(key), decoded=decoded)
        except (OSError, UserError):
            pass
    return decoded
