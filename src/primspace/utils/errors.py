"""Errors that a user can fix: the command line prints them as one line and exits 2.

Library code raises these (they subclass :class:`ValueError`, so scikit-learn style
callers that catch ``ValueError`` keep working); the ``primspace`` command catches
:class:`UserError` at the top, prints ``primspace: error: <message>`` and exits with
status 2, without a traceback. Anything else that escapes is a bug and keeps its
traceback.
"""

from __future__ import annotations

import os

__all__ = ["UserError", "DataError", "OutputExistsError", "first_line", "config_from_dict"]


class UserError(ValueError):
    """A problem with the user's input, arguments or files, fixable by the user."""


class DataError(UserError):
    """Invalid data, located by file, field and (when it applies) sample index.

    Parameters
    ----------
    message : str
        What is wrong, e.g. ``"contains NaN or inf"``.
    path : str or os.PathLike, optional
        The file the data came from (or will go to).
    field : str, optional
        The data set field (``motor``, ``images``, ``labels`` ...).
    index : int, optional
        The sample index within the field.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | os.PathLike | None = None,
        field: str | None = None,
        index: int | None = None,
    ) -> None:
        self.reason = message
        self.path = None if path is None else os.fspath(path)
        self.field = field
        self.index = index
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.path is not None:
            where.append(self.path)
        if self.field is not None:
            where.append(f"field '{self.field}'")
        if self.index is not None:
            where.append(f"sample {self.index}")
        prefix = ", ".join(where)
        return f"{prefix}: {self.reason}" if prefix else self.reason

    def located(
        self,
        *,
        path: str | os.PathLike | None = None,
        field: str | None = None,
        index: int | None = None,
    ) -> DataError:
        """Return a copy with missing location parts filled in (existing ones win)."""
        return DataError(
            self.reason,
            path=self.path if self.path is not None else path,
            field=self.field if self.field is not None else field,
            index=self.index if self.index is not None else index,
        )


class OutputExistsError(UserError):
    """An output file or directory exists and overwriting was not asked for."""

    def __init__(self, path: str | os.PathLike, hint: str = "--overwrite") -> None:
        self.path = os.fspath(path)
        super().__init__(f"{self.path}: output exists; pass {hint} to replace it")


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (library errors can run to many lines)."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def config_from_dict(cls, d: dict, what: str):
    """Build the dataclass ``cls`` from a JSON dict, refusing fields it does not know.

    A checkpoint or preset written by another version fails with one line that names
    the fields (``what``: "model config", "train config") instead of a TypeError.
    """
    from dataclasses import fields

    unknown = sorted(set(d) - {f.name for f in fields(cls)})
    if unknown:
        raise UserError(f"unknown {what} field(s): {', '.join(unknown)}")
    return cls(**d)
