"""Exception types raised by :mod:`hdid`.

Every error meant for the end user derives from :class:`HdidError`, so a
command-line front end can catch that one class and print ``str(err)``.
"""

from __future__ import annotations

import functools
import os

__all__ = ["HdidError", "LogError"]


def _one_line(text: str) -> str:
    """Collapse any line breaks in `text` into single spaces."""
    return " ".join(str(text).splitlines()).strip()


class HdidError(Exception):
    """Base class of all errors raised deliberately by hdid."""


class LogError(HdidError, ValueError):
    """Bad input log (or a bad request about one).

    ``str(err)`` is always a single line of the form::

        {path}: column 'theta', row 17: cell is empty — fill it or drop the row

    naming the file (``<DataFrame>`` for in-memory input), the column and/or the
    row where the problem is, what is wrong and what to do about it. ``row`` is
    the 1-based line number in the CSV file counting the header line, so the
    first data row is row 2.

    Parameters
    ----------
    message : str
        What is wrong and what to do (without the location prefix).
    path : str or os.PathLike, optional
        The file concerned; ``None`` means a :class:`pandas.DataFrame` input.
    column : str, optional
        Name of the column concerned.
    row : int, optional
        1-based line number in the CSV file (header is row 1).

    Attributes
    ----------
    message : str
        The message without the location prefix (one line).
    path, column, row
        As given.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | os.PathLike[str] | None = None,
        column: str | None = None,
        row: int | None = None,
    ) -> None:
        self.message = _one_line(message)
        self.path = path
        self.column = column
        self.row = row
        super().__init__(self._format())

    @property
    def source(self) -> str:
        """The file name as shown in the message (``<DataFrame>`` if none)."""
        if self.path is None:
            return "<DataFrame>"
        try:
            return _one_line(os.fspath(self.path))
        except TypeError:
            return _one_line(str(self.path))

    def _format(self) -> str:
        where = []
        if self.column is not None:
            where.append(f"column {_one_line(repr(str(self.column)))}")
        if self.row is not None:
            where.append(f"row {self.row}")
        prefix = self.source + (": " + ", ".join(where) if where else "")
        return f"{prefix}: {self.message}"

    def __str__(self) -> str:
        return self._format()

    def __reduce__(self):  # keep keyword attributes through pickling
        rebuild = functools.partial(
            type(self), path=self.path, column=self.column, row=self.row
        )
        return (rebuild, (self.message,))


class FitError(HdidError, RuntimeError):
    """A fit that cannot be done or did not work (diverged, too few samples)."""
