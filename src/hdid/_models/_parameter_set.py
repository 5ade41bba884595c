"""Named physical parameters with their declarations: what a free-motion :class:`Model`, a
:class:`DrivenJoint` and its :class:`PositionalError` share (values by name, a float copy,
``replace`` with a clear error for an unknown name)."""

# (no ``from __future__ import annotations``: equinox reads the abstract methods' class)
import abc
from typing import Any

import equinox as eqx

from ..effects import Parameter


class AbstractParameterSet(eqx.Module):
    """Parameters by name. Subclasses give the declarations (:meth:`parameter_specs`), the
    values (:meth:`values`) and a copy with some values replaced (:meth:`_replaced`, only
    ever called with names of this set)."""

    @abc.abstractmethod
    def parameter_specs(self) -> dict[str, Parameter]:
        """Every parameter's declaration (unit, doc, transform, prior, start) by name."""

    @abc.abstractmethod
    def values(self) -> dict[str, Any]:
        """Parameter values by name (arrays or floats as stored)."""

    @abc.abstractmethod
    def _replaced(self, values: dict[str, Any]) -> "AbstractParameterSet":
        """A copy with ``values`` (names of this set only) replaced."""

    def names(self) -> tuple[str, ...]:
        return tuple(self.parameter_specs())

    def float_values(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.values().items()}

    def replace(self, **values) -> "AbstractParameterSet":
        """A copy with some parameter values replaced (same structure)."""
        specs = self.parameter_specs()
        unknown = set(values) - set(specs)
        if unknown:
            raise KeyError(f"unknown parameter(s) {sorted(unknown)}; this "
                           f"{type(self).__name__} has {list(specs)}")
        return self._replaced(values)
