"""A stored summary's command as the docs print it: one a reader can run on any machine.

A summary keeps the commands exactly as they ran (``primspace summarize``), with the paths
of the machine that ran them. The docs print them with those paths replaced by named
placeholders: the experiment folder (``--out``/``-o``) by ``OUT``, a path inside it by
``OUT/<the rest>``, the data file (``--data``) by ``DATA`` and its suffix (``DATA.h5``),
any other absolute path by its option's name in capitals (``--json /tmp/a.json`` ->
``JSON.json``) or ``PATH`` and its suffix. Relative paths and everything else are kept
as written. A command the CLI no longer has (:data:`RETIRED`) is kept, as history, with
a comment that says so.
"""

from __future__ import annotations

import re
from pathlib import PurePosixPath

__all__ = ["OUT", "DATA", "RETIRED", "portable_command"]

#: The placeholder of the experiment folder.
OUT = "OUT"
#: The placeholder of the data file, before its suffix.
DATA = "DATA"

#: Commands the CLI no longer has, and the release that retired them.
RETIRED = {"primspace experiment scene": "0.9.0"}

_OUT_OPTIONS = ("--out", "-o")
#: A path of one machine: from the root, the home (``~``) or a drive (``C:\``).
_ABSOLUTE = re.compile(r"^(/|~|[A-Za-z]:[\\/])")


def _placeholder(path: str, option: str | None, out: str | None) -> str:
    if option in _OUT_OPTIONS:
        return OUT
    if out is not None and path != out and path.startswith(out.rstrip("/") + "/"):
        return f"{OUT}/{path[len(out.rstrip('/')) + 1 :]}"
    suffix = PurePosixPath(path.replace("\\", "/")).suffix
    if option == "--data":
        return DATA + suffix
    name = option.lstrip("-").replace("-", "_").upper() if option else "PATH"
    return name + suffix


def _portable_line(line: str) -> str:
    parts = re.split(r"(\s+)", line)  # words and the white space between them, kept
    words = parts[::2]
    options = [None] + [w if w.startswith("-") else None for w in words[:-1]]
    outs = [w for o, w in zip(options, words) if o in _OUT_OPTIONS]
    outs += [w.partition("=")[2] for w in words if w.partition("=")[0] in _OUT_OPTIONS]
    out = next((w for w in outs if _ABSOLUTE.match(w)), None)
    for i, (option, word) in enumerate(zip(options, words)):
        flag, eq, value = word.partition("=")
        if eq and flag.startswith("-") and _ABSOLUTE.match(value):
            parts[2 * i] = f"{flag}={_placeholder(value, flag, out)}"
        elif _ABSOLUTE.match(word):
            parts[2 * i] = _placeholder(word, option, out)
    retired = next((v for c, v in RETIRED.items() if line.split()[:3] == c.split()), None)
    return "".join(parts) + (f"  # retired in {retired}: no longer runs" if retired else "")


def portable_command(command: str) -> str:
    """``command`` (one or more lines) with every absolute path replaced by its named
    placeholder and every retired one marked (module docstring); any other command is
    returned as it is."""
    return "\n".join(_portable_line(line) for line in command.split("\n"))
