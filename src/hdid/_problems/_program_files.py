"""The program store's files (:mod:`hdid._problems._programs`): where they live, what
every key shares (:func:`_salt`), and the stored versions of a key, each with the record
of what its trace ran (:mod:`hdid._problems._program_deps`).

Layout of ``<cache>/programs/<salt>/``: ``<key>.deps`` (one JSON line per stored version:
its id and dependency record), ``<key>.<id>.exp`` (the program, a pickled
:mod:`jax.export` ``Exported``), ``<key>.<id>.bad`` (failed to run: never loaded again)
and ``<key>.bad`` (cannot be exported: never traced for the store again).
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import sys
import time
from pathlib import Path

import jax

from .. import _config
from . import _program_deps

_SALT: str | None = None

#: The store's layout: ``<key>.deps`` (one JSON line per stored version of the program:
#: its id and :func:`hdid._problems._program_deps.record`), ``<key>.<id>.exp`` (the
#: program), ``<key>.<id>.bad`` (failed to run: never loaded again), ``<key>.bad``
#: (cannot be exported: never traced for the store again). Part of :func:`_salt`.
FORMAT = "deps-1"
#: Stored versions kept per key (older ones are removed when a new one is written).
MAX_VERSIONS = 4

#: Installed packages whose version is part of every key (what traces run besides hdid;
#: any other installed package a trace runs is recorded with the program).
VERSIONED = ("jax", "jaxlib", "equinox", "optimistix", "lineax", "jaxtyping", "numpy",
             "scipy", "hdid")


def _salt() -> str:
    """What every program depends on besides its own trace: the store's :data:`FORMAT`,
    Python's and the :data:`VERSIONED` packages' versions, the backend and equinox's
    error mode (``EQX_ON_ERROR``; float64 is in each key: a thread-local switch). hdid's
    source is not here: each program records the files its trace ran
    (:mod:`hdid._problems._program_deps`)."""
    global _SALT
    if _SALT is None:
        from importlib import metadata

        h = hashlib.sha256()
        h.update(f"{FORMAT}|{sys.version}".encode())
        for name in VERSIONED:
            try:
                h.update(f"|{name}=={metadata.version(name)}".encode())
            except metadata.PackageNotFoundError:
                h.update(f"|{name}".encode())
        dev = jax.devices()[0]
        h.update(f"|{dev.platform}:{getattr(dev, 'device_kind', '')}".encode())
        h.update(f"|eqx={os.environ.get('EQX_ON_ERROR', '')}".encode())
        _SALT = h.hexdigest()
    return _SALT


#: A folder of programs of another source (or JAX) not used for this long is removed.
STALE_DAYS = 7.0


def _store() -> Path | None:
    """The store's folder for this source and JAX (``<cache>/programs/<salt>``), or
    ``None`` (``HDID_NO_CACHE=1``, ``HDID_PROGRAM_STORE=0``, or a process whose JAX
    persistent compilation cache is off: without :func:`hdid.configure` the library
    writes nothing to disk, and a stored program would be compiled again anyway)."""
    if os.environ.get("HDID_NO_CACHE") or os.environ.get("HDID_PROGRAM_STORE") == "0":
        return None
    if jax.config.jax_compilation_cache_dir is None:
        return None
    root = _config._cache_dir() / "programs"
    path = root / _salt()[:16]
    if not path.is_dir():
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError:
            return None
        _prune(root, path)
    return path


def _prune(root: Path, keep: Path) -> None:
    """Remove other versions' folders unused for :data:`STALE_DAYS` (a new folder is made
    for every new JAX, Python or hdid version)."""
    now = time.time()
    for d in root.iterdir():
        try:
            if d != keep and d.is_dir() and now - d.stat().st_mtime > STALE_DAYS * 86400:
                for f in d.iterdir():
                    f.unlink()
                d.rmdir()
        except OSError:
            pass


def _versions(store: Path, key: str) -> list[dict]:
    """The stored versions of ``key``, oldest first (unreadable lines skipped)."""
    try:
        lines = (store / f"{key}.deps").read_text().splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        try:
            v = json.loads(line)
        except ValueError:
            continue
        if isinstance(v, dict) and isinstance(v.get("id"), str) and isinstance(v.get("deps"), dict):
            out.append(v)
    return out


def _add_version(store: Path, key: str, vid: str, rec: dict) -> None:
    """Append a stored version of ``key``; keep the newest :data:`MAX_VERSIONS`."""
    old = [v for v in _versions(store, key) if v["id"] != vid]
    line = json.dumps({"id": vid, "deps": rec}, sort_keys=True)
    if len(old) < MAX_VERSIONS:
        with open(store / f"{key}.deps", "a") as f:
            f.write(line + "\n")
        return
    keep = old[-(MAX_VERSIONS - 1):]
    tmp = store / f"{key}.deps.{os.getpid()}.tmp"
    tmp.write_text("".join(json.dumps(v, sort_keys=True) + "\n" for v in keep) + line + "\n")
    os.replace(tmp, store / f"{key}.deps")
    for v in old[:-(MAX_VERSIONS - 1)]:
        for suffix in (".exp", ".bad"):
            try:
                (store / f"{key}.{v['id']}{suffix}").unlink()
            except OSError:
                pass


def _find(key: str, given=None) -> str | None:
    """The stored version of ``key`` whose recorded dependencies all hold in this process
    (``<key>.<id>``, newest first), or ``None``; ``given()``: the files defining what the
    call is given (:func:`hdid._problems._program_deps.matches`). A version that does not hold
    is noted with its reason (:data:`hdid._problems._program_deps.MISSES`)."""
    store = _store()
    if store is None or (store / f"{key}.bad").exists():
        return None
    for v in reversed(_versions(store, key)):
        stem = f"{key}.{v['id']}"
        if (store / f"{stem}.exp").exists() and not (store / f"{stem}.bad").exists():
            why = _program_deps.mismatch(v["deps"], given)
            if why is None:
                return stem
            _program_deps.missed(stem, why)
    return None


def _mark_bad(stem: str) -> None:
    """Never load (``<key>.<id>``) or never export (``<key>``) again."""
    store = _store()
    if store is not None:
        try:
            (store / f"{stem}.bad").touch()
        except OSError:
            pass


def _load(stem: str):
    """The stored ``Exported`` ``<key>.<id>`` (:func:`_find`), or ``None``."""
    store = _store()
    if store is None:
        return None
    path = store / f"{stem}.exp"
    if not path.exists() or (store / f"{stem}.bad").exists():
        return None
    try:
        return pickle.loads(path.read_bytes())
    except Exception:  # noqa: BLE001 - stale or unreadable: trace again
        return None


