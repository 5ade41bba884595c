"""The library of effects, built from the files: every public module of this package is one
effect whose file stem is its ``key`` (the ``--add`` name), and third-party packages add
theirs through the ``hdid.effects`` entry-point group (name = key, value = the module or
the class). Adding a library effect is one new file."""

from __future__ import annotations

import functools
import importlib
import pkgutil
from importlib.metadata import entry_points
from pathlib import Path

from ._base import AbstractEffect

GROUP = "hdid.effects"
_HERE = Path(__file__).resolve().parent


def builtin_keys() -> list[str]:
    """The library's keys from the file names alone (no import: ``hdid --help`` stays fast)."""
    return sorted(m.name for m in pkgutil.iter_modules([str(_HERE)]) if not m.name.startswith("_"))


def plugin_keys() -> list[str]:
    """Keys that installed packages register under the ``hdid.effects`` entry-point group."""
    return sorted(ep.name for ep in entry_points(group=GROUP))


def keys() -> list[str]:
    """Every ``--add`` name: the library's files and the installed plugins'."""
    return sorted(set(builtin_keys()) | set(plugin_keys()))


def _effect_in(obj, key: str, where: str) -> type[AbstractEffect]:
    if isinstance(obj, type) and issubclass(obj, AbstractEffect):
        found = [obj]
    else:  # a module: its one effect class whose key is ``key``
        found = [v for v in vars(obj).values() if isinstance(v, type)
                 and issubclass(v, AbstractEffect) and v.__dict__.get("key") == key]
    if len(found) != 1:
        raise ImportError(f"{where}: expected one AbstractEffect subclass with key = {key!r}, "
                          f"found {len(found)}")
    cls = found[0]
    if cls.key != key:
        raise ImportError(f"{where}: {cls.__name__}.key is {cls.key!r}, not {key!r}")
    return cls


@functools.cache
def registry() -> dict[str, type[AbstractEffect]]:
    """key → effect class, the library's first; a plugin cannot replace a library key."""
    out: dict[str, type[AbstractEffect]] = {}
    for key in builtin_keys():
        out[key] = _effect_in(importlib.import_module(f"{__package__}.{key}"), key,
                              f"hdid/effects/{key}.py")
    for ep in entry_points(group=GROUP):
        if ep.name in out:
            raise ImportError(f"entry point {ep.name!r} ({ep.value}) of group {GROUP!r}: "
                              "the name of a library effect; choose another")
        out[ep.name] = _effect_in(ep.load(), ep.name, f"entry point {ep.name} = {ep.value}")
    return out
