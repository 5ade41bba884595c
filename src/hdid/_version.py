"""hdid's version, in the base layer so that any module may name it (a result file records
the hdid that wrote it) without importing the package's public namespace."""

from __future__ import annotations


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hdid")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


__version__ = _version()
