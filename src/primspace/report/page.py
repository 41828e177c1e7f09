"""The HTML page: headings, paragraphs, notes, tables and embedded figures (PNG, animated GIF).

:class:`HtmlReport` knows nothing of experiments; :mod:`primspace.report.sections` fills
it from an experiment directory's results. (Named ``page``, not ``html``, so that it
never shadows the standard library's :mod:`html`, which it uses.)
"""

from __future__ import annotations

import base64
import html
import os
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from primspace.utils.files import atomic_write_text

__all__ = ["HtmlReport"]

# the figure files a report embeds, by suffix
_MIME = {".png": "image/png", ".gif": "image/gif"}

_CSS = """
body { font-family: -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif; margin: 0 auto;
       max-width: 1100px; padding: 1.5em 2em 4em; color: #222; line-height: 1.45; }
h1 { font-size: 1.7em; margin-bottom: 0.1em; } h2 { border-bottom: 1px solid #ddd; padding-bottom: .2em;
     margin-top: 2em; } h3 { margin-top: 1.4em; }
.sub { color: #666; margin-top: 0; }
table { border-collapse: collapse; margin: .8em 0 1.2em; font-size: .92em; }
th, td { border: 1px solid #ddd; padding: .3em .7em; text-align: left; }
th { background: #f4f4f4; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
caption { caption-side: bottom; color: #555; font-size: .9em; padding-top: .3em; text-align: left; }
figure { margin: 1em 0 1.6em; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { color: #555; font-size: .9em; }
pre { background: #f7f7f7; padding: .8em; overflow-x: auto; font-size: .85em; }
.note { padding: .6em 1em; border-left: 4px solid #3b82f6; background: #eff6ff; margin: 1em 0; }
.warn { border-left-color: #d97706; background: #fffbeb; }
.good { border-left-color: #16a34a; background: #f0fdf4; }
nav a { margin-right: 1em; }
"""


class HtmlReport:
    """Build an HTML page from headings, text, tables and PNG or GIF figures.

    Examples
    --------
    >>> r = HtmlReport("Title")
    >>> r.section("Results")
    >>> r.table(["init", "loss"], [["zero", 0.5]])
    >>> "<table>" in r.render()
    True
    """

    def __init__(self, title: str, subtitle: str = "", root: str | Path | None = None) -> None:
        self.title = title
        self.subtitle = subtitle
        self.root = None if root is None else Path(root)  # figures come from inside it, or are left out
        self._parts: list[str] = []
        self._toc: list[tuple[str, str]] = []

    def section(self, title: str) -> None:
        anchor = "s" + str(len(self._toc))
        self._toc.append((anchor, title))
        self._parts.append(f'<h2 id="{anchor}">{html.escape(title)}</h2>')

    def subsection(self, title: str) -> None:
        self._parts.append(f"<h3>{html.escape(title)}</h3>")

    def paragraph(self, text: str) -> None:
        self._parts.append(f"<p>{html.escape(text)}</p>")

    def note(self, text: str, kind: str = "note") -> None:
        """A highlighted box; ``kind`` is ``note``, ``warn`` or ``good``."""
        cls = {"warn": "note warn", "good": "note good"}.get(kind, "note")
        self._parts.append(f'<div class="{cls}">{html.escape(text)}</div>')

    def table(self, columns: Sequence[str], rows: Sequence[Sequence[Any]], caption: str = "") -> None:
        head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
        body = "".join("<tr>" + "".join(_cell(v) for v in row) + "</tr>" for row in rows)
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self._parts.append(f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")

    def figure(self, image: str | Path, caption: str = "") -> None:
        """Embed a PNG or (animated) GIF file (skipped with a note if it does not exist).

        Only a regular file inside ``root`` (the experiment folder; without one, the
        figure's own folder) is embedded: a symbolic link, or a file that resolves outside,
        is left out with a visible note, and what it points to is never read, so no file
        from elsewhere on the machine ends up in a report that is shared.
        """
        image = Path(image)
        refused = self._refused(image)
        if refused:
            self.note(f"figure not embedded: {image.name} {refused}", "warn")
            return
        if not image.exists():
            self.note(f"figure missing: {image.name}", "warn")
            return
        mime = _MIME.get(image.suffix.lower())
        if mime is None:
            raise ValueError(f"{image.name}: only {', '.join(_MIME)} figures can be embedded")
        data = _read_regular(image)
        if data is None:
            self.note(f"figure not embedded: {image.name} is not a regular file", "warn")
            return
        data = base64.b64encode(data).decode("ascii")
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self._parts.append(
            f'<figure><img alt="{html.escape(image.stem)}" src="data:{mime};base64,{data}">{cap}</figure>'
        )

    def _refused(self, image: Path) -> str:
        """Why ``image`` may not be embedded ("" if it may): a link, or outside ``root``."""
        if image.is_symlink():
            return "is a symbolic link (only regular files inside the experiment folder are embedded)"
        if not image.exists():
            return ""
        base = (self.root if self.root is not None else image.parent).resolve()
        if not image.resolve().is_relative_to(base):
            return "lies outside the experiment folder (a folder on its path is a symbolic link)"
        return ""

    def code(self, text: str) -> None:
        self._parts.append(f"<pre>{html.escape(text)}</pre>")

    def render(self) -> str:
        nav = " ".join(f'<a href="#{a}">{html.escape(t)}</a>' for a, t in self._toc)
        sub = f'<p class="sub">{html.escape(self.subtitle)}</p>' if self.subtitle else ""
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{html.escape(self.title)}</h1>{sub}<nav>{nav}</nav>" + "\n".join(self._parts) + "</body></html>\n"
        )

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        atomic_write_text(path, self.render())
        return path


def _read_regular(path: Path) -> bytes | None:
    """The bytes of ``path`` if it is a regular file, not following a link at its last
    component (checked again on the open file), else None; a FIFO does not block."""
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as fh:
        return fh.read() if stat.S_ISREG(os.fstat(fh.fileno()).st_mode) else None


def _cell(v: Any) -> str:
    numeric = isinstance(v, (int, float)) and not isinstance(v, bool)
    return f'<td class="num">{html.escape(_fmt(v))}</td>' if numeric else f"<td>{html.escape(_fmt(v))}</td>"


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        if v != v:  # NaN
            return "–"
        return f"{v:.4g}"
    return str(v)
