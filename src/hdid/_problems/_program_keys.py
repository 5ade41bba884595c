"""The program store's keys without their cost (:mod:`hdid._problems._programs`, issue 37).

A stored program's key (``_programs._key``) is a hash of text — the name, the arguments'
tree with every static field, their shapes and dtypes, float64, the versions — and costs
~0.1–0.3 ms a call; a fit makes tens of calls with the same kinds of arguments. Here a
cheap hashable description of a call (:func:`memo_key`) maps to its key once computed
(:func:`lookup`, :func:`remember`); a problem or model passed again (the same object) is
described once. The description holds everything the key reads, so two calls share a key
here only where ``_key`` would give them the same one.
"""

from __future__ import annotations

from collections import OrderedDict

import equinox as eqx
import jax

#: The key of calls seen before in this process, by their description (:func:`memo_key`).
#: Bounded, most recently used last.
KEYS: OrderedDict[tuple, str] = OrderedDict()
MAX_KEYS = 512


def _describe(tree):
    """``(description, leaves)`` of one argument for :func:`memo_key`: its tree (static
    fields included) and the tree's text (equal static fields can print apart, 1 and 1.0,
    as the key sees them), which leaves are arrays, the other leaves (each with its type,
    floats by their bits, so ``0.0`` and ``-0.0`` stay apart) and the arrays' shapes,
    dtypes and weak types; ``leaves``: the arrays."""
    flat, treedef = jax.tree_util.tree_flatten(tree)
    mask = tuple(eqx.is_array(x) for x in flat)
    leaves = [x for x, a in zip(flat, mask) if a]
    others = tuple((type(x), x.hex() if isinstance(x, float) else x)
                   for x, a in zip(flat, mask) if not a)
    avals = tuple((x.shape, x.dtype, bool(getattr(x, "weak_type", False))) for x in leaves)
    return (treedef, str(treedef), mask, others, avals), leaves


#: :func:`_describe` of modules (a problem, a model) by identity, with a small integer
#: standing for the description (hashing a problem's tree costs ~0.1 ms, tens of calls a
#: fit pass the same problem). Modules are immutable; the entry keeps the module alive, so
#: its ``id`` is not reused while cached.
MODULES: OrderedDict[int, tuple] = OrderedDict()
MAX_MODULES = 32
#: Description → its integer (:data:`MODULES`); cleared with :data:`KEYS` when full.
TOKENS: dict[tuple, int] = {}
MAX_TOKENS = 4096


def _described(arg):
    """``(part, leaves)`` of one argument for :func:`memo_key`: a module's integer
    (:data:`TOKENS`), any other argument's :func:`_describe`."""
    if not isinstance(arg, eqx.Module):
        return _describe(arg)
    got = MODULES.get(id(arg))
    if got is not None and got[0] is arg:
        _touch(MODULES, id(arg))
        return got[1], got[2]
    desc, leaves = _describe(arg)
    try:
        if len(TOKENS) >= MAX_TOKENS:  # (memos name tokens: all go together)
            TOKENS.clear()
            KEYS.clear()
            MODULES.clear()
        token = ("module", TOKENS.setdefault(desc, len(TOKENS)))
    except TypeError:  # unhashable: described each time (and no memo, memo_key)
        return desc, leaves
    MODULES[id(arg)] = (arg, token, leaves)
    while len(MODULES) > MAX_MODULES:
        try:
            MODULES.popitem(last=False)
        except KeyError:  # emptied by another thread
            break
    return token, leaves


def memo_key(name: str, args):
    """``(memo, leaves)``: the arrays of ``args`` (the dynamic leaves, in the order of
    ``eqx.partition(args, eqx.is_array)``'s flattening) and a hashable description of
    everything the key reads (:func:`_described`, argument by argument, and float64,
    a thread-local switch). ``memo`` is
    ``None`` where some part is unhashable."""
    parts, leaves = [], []
    for arg in args:
        d, lv = _described(arg)
        parts.append(d)
        leaves.extend(lv)
    memo = (name, bool(jax.config.jax_enable_x64), tuple(parts))
    try:
        hash(memo)
    except TypeError:
        return None, leaves
    return memo, leaves


def lookup(memo) -> str | None:
    """The key remembered for ``memo`` (:func:`memo_key`), or ``None``."""
    if memo is None:
        return None
    key = KEYS.get(memo)
    if key is not None:
        _touch(KEYS, memo)
    return key


def _touch(d: OrderedDict, k) -> None:
    """Mark ``k`` recently used (gone already where another thread evicted it: fine)."""
    try:
        d.move_to_end(k)
    except KeyError:
        pass


def remember(memo, key: str) -> None:
    """Remember ``key`` for ``memo`` (nothing where ``memo`` is ``None``)."""
    if memo is None:
        return
    KEYS[memo] = key
    while len(KEYS) > MAX_KEYS:
        try:
            KEYS.popitem(last=False)
        except KeyError:  # emptied by another thread
            break
