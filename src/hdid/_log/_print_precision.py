"""How a numeric column is printed (:func:`print_precision`): fixed decimals or significant
digits, and the print unit of every cell (:mod:`._resolution` finds the encoder step
within it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


#: A printed number: sign, integer digits, optional decimals, optional exponent.
_NUMBER = r"^\s*[-+]?(?P<int>\d*)(?:\.(?P<dec>\d*))?(?:[eE](?P<exp>[-+]?\d+))?\s*$"


@dataclass(frozen=True)
class PrintPrecision:
    """How a numeric column is printed.

    ``kind`` is ``"decimals"`` (every cell with ``value`` decimals, or whole numbers with
    ``value`` 0) or ``"digits"`` (``value`` significant digits: ``%g``, scientific notation,
    Python's shortest ``repr``). ``unit`` is the finest print unit of the column in the
    column's own units (``10**-decimals``; for digits, that of the smallest nonzero
    reading); ``per_cell`` the print unit of every cell (the rounding of a cell is at most
    half of it)."""

    kind: str
    value: int
    unit: float
    per_cell: np.ndarray

    def scaled(self, factor: float) -> PrintPrecision:
        """The same precision in units ``factor`` times the column's (a header unit)."""
        return PrintPrecision(self.kind, self.value, self.unit * factor, self.per_cell * factor)

    def describe(self, unit_name: str = "") -> str:
        """``1e-08 rad`` or ``6 significant digits`` (for a message)."""
        if self.kind == "digits":
            return f"{self.value} significant digits"
        return f"{self.unit:.3g}{(' ' + unit_name) if unit_name else ''}"


def print_precision(cells) -> PrintPrecision | None:
    """The printing precision of a column of numeric text cells, or ``None`` (cells that
    are not text — a DataFrame's numbers — or not plain numbers).

    Each cell's last written digit sits at ``10**(exponent − decimals)``. A column whose
    every cell has the same number of decimals and no exponent is printed with fixed
    decimals. Otherwise it is printed to significant digits ``S`` (the most any cell
    shows, since ``%g`` and ``repr`` drop trailing zeros), and a cell whose leading digit
    is at ``10**m`` is rounded to ``10**(m − S + 1)``, but never finer than the finest
    digit any cell shows.
    """
    cells = np.asarray(cells, dtype=object)
    if cells.size == 0 or not all(isinstance(c, str) for c in cells[: min(cells.size, 50)]):
        return None
    # a log repeats its levels: parse each distinct text once
    codes, raw = pd.factorize(pd.Series(cells, dtype=object).astype(str))
    found = _precision_of(np.asarray(raw, dtype=object))
    if found is None:
        return None
    return PrintPrecision(found.kind, found.value, found.unit, found.per_cell[codes])


def _precision_of(raw: np.ndarray) -> PrintPrecision | None:
    """:func:`print_precision` of distinct cells."""
    parts = pd.Series(raw, dtype=object).str.extract(_NUMBER)
    if parts["int"].isna().any():
        return None
    ints = parts["int"].fillna("").to_numpy(dtype=str)
    decs = parts["dec"].fillna("").to_numpy(dtype=str)
    has_exp = parts["exp"].notna().to_numpy()
    exps = parts["exp"].fillna("0").astype(int).to_numpy()
    n_dec = np.char.str_len(decs.astype(str))
    last = exps - n_dec  # power of ten of the last written digit
    finest = int(last.min())
    if not has_exp.any() and np.all(n_dec == n_dec[0]):
        unit = 10.0 ** (-int(n_dec[0]))
        return PrintPrecision("decimals", int(n_dec[0]), unit, np.full(raw.size, unit))
    digits = np.char.add(ints.astype(str), decs.astype(str))
    stripped = np.char.lstrip(digits, "0")
    n_sig = np.char.str_len(stripped)
    # power of ten of the leading digit: the digits before the point, less the zeros
    lead = exps + np.char.str_len(ints.astype(str)) - 1 - (np.char.str_len(digits) - n_sig)
    sig = int(n_sig.max())
    if sig == 0:  # every cell is zero
        unit = 10.0**finest
        return PrintPrecision("decimals", max(-finest, 0), unit, np.full(raw.size, unit))
    per_cell = 10.0 ** np.maximum(np.where(n_sig > 0, lead - sig + 1, finest), finest)
    nonzero = per_cell[n_sig > 0]
    return PrintPrecision("digits", sig, float(nonzero.min()), per_cell.astype(float))
