"""The program store's key is computed once per kind of call (issue 37: the key's text and
hash cost ~0.3 ms a call, tens of calls a fit): a call with new values of the same shapes
reuses it, and the memo still tells apart what the key tells apart."""

from __future__ import annotations

from collections import OrderedDict

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from hdid._problems import _program_keys, _programs


class _Gain(eqx.Module):
    k: jnp.ndarray
    sign: float = eqx.field(static=True)


def _scaled(gain, x):
    return jnp.copysign(1.0, gain.sign) * gain.k * x


@pytest.fixture
def counted(monkeypatch):
    """The number of times the key's text is hashed (``_programs._key``), in a process
    with nothing compiled or memoised yet."""
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())
    monkeypatch.setattr(_program_keys, "KEYS", OrderedDict())
    monkeypatch.setattr(_program_keys, "MODULES", OrderedDict())
    monkeypatch.setattr(_program_keys, "TOKENS", {})
    n = [0]
    real = _programs._key

    def key(*a):
        n[0] += 1
        return real(*a)

    monkeypatch.setattr(_programs, "_key", key)
    return n


def test_a_warm_call_does_not_hash_the_key_again(counted):
    gain = _Gain(jnp.asarray(2.0), 1.0)
    _programs.call("scaled", _scaled, gain, np.arange(3.0))
    assert counted[0] == 1
    for x in (np.arange(3.0) + 1, np.ones(3)):  # new values, same shapes: same program
        np.testing.assert_array_equal(_programs.call("scaled", _scaled, gain, x), 2.0 * x)
    # a new module of the same structure (another fit of the same model) too
    out = _programs.call("scaled", _scaled, _Gain(jnp.asarray(3.0), 1.0), np.ones(3))
    np.testing.assert_array_equal(out, 3.0 * np.ones(3))
    assert counted[0] == 1


def test_the_memo_keeps_apart_what_the_key_keeps_apart(counted):
    x = np.ones(3)
    plus, minus = (np.asarray(_programs.call("scaled", _scaled, _Gain(jnp.asarray(1.0), s), x))
                   for s in (0.0, -0.0))  # equal floats, different static fields: two programs
    np.testing.assert_array_equal(plus, x)
    np.testing.assert_array_equal(minus, -x)
    out = _programs.call("scaled", _scaled, _Gain(jnp.asarray(1.0), 1.0), np.ones(4))
    assert out.shape == (4,)  # another shape: another program
    assert counted[0] == 3
