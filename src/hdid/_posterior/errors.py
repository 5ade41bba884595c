"""The posterior's own error: a request it cannot sample, said in one line.

:class:`PosteriorError` is an :class:`~hdid.HdidError` (the command line prints it as one
line, exit 2, no traceback) and a :class:`ValueError` (what these errors were before, so
code that caught that still does). Each message names the Python argument and the
command-line flag, e.g. ``n_walkers (--walkers) = 4: ...``.
"""

from __future__ import annotations

from .._errors import HdidError, _one_line


class PosteriorError(HdidError, ValueError):
    """A posterior that cannot be sampled as asked (bad option, no start of positive
    density, a numerical failure of the sampler); ``str(err)`` is one line."""

    def __init__(self, message: str):
        super().__init__(_one_line(message))
