"""A MATLAB ``.mat`` file as a log table: its vectors named like the log's columns.

Test benches driven from MATLAB/Simulink save their signals as vectors in a ``.mat`` file
(``time``, ``theta``, …; a bare ``t`` is ``time``, and the column names may carry a unit
suffix such as ``time_ms`` or ``theta_deg``, :mod:`._headers`). The vectors named like
one of the log's columns become the table's columns, in the order the file holds them,
each sample a row; row ``k`` in a message is sample ``k - 1`` (as the table would be
numbered as a CSV file with a header line). Files saved with ``-v7.3`` (HDF5) are not
read by :func:`scipy.io.loadmat`: the error says to save them with ``-v7`` or as CSV.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd

from .._errors import LogError
from ._headers import header_key
from ._names import _KNOWN_COLUMNS, _TIME


def load_mat_frame(path: str | os.PathLike[str]) -> pd.DataFrame:
    """The ``.mat`` file's vectors named like log columns, as a DataFrame (or a LogError)."""
    from scipy import io as sio  # light: only a .mat log imports it

    err = lambda message: LogError(message, path=path)  # noqa: E731
    try:
        data = sio.loadmat(os.fspath(path), squeeze_me=True, chars_as_strings=True)
    except FileNotFoundError:
        raise err("file not found — check the path") from None
    except NotImplementedError:
        raise err("a MATLAB -v7.3 (HDF5) file — save it with save(..., '-v7') or export "
                  "the log as CSV") from None
    except Exception as exc:  # scipy raises assorted errors on a damaged file
        raise err(f"cannot read it as a MATLAB .mat file ({type(exc).__name__}) — save it "
                  "again from MATLAB, or export the log as CSV") from None
    names = [k for k in data if not k.startswith("__")]
    arrays = {k: np.atleast_1d(np.asarray(data[k])) for k in names}
    shown = ", ".join(repr(k) for k in names) or "none"
    time = next((k for k in arrays if header_key(k)[0] == _TIME), None)
    if time is None or arrays[time].ndim != 1:
        raise err(f"no vector named 'time' (or 't'): found variables [{shown}] — name the "
                  "time vector 'time' and the angle 'theta' (units as a suffix: time_ms, "
                  "theta_deg), or export the log as CSV")
    n = arrays[time].size
    for k, v in arrays.items():
        if header_key(k)[0] in _KNOWN_COLUMNS and (v.ndim != 1 or v.size != n):
            raise err(f"variable {k!r} holds {v.shape} values but {time!r} holds {n} — "
                      "every log vector must have one value per sample")
    # every vector of one value per sample is a column (unknown names are listed in a
    # missing-column error and otherwise ignored, as a CSV file's other columns)
    return pd.DataFrame({k: (v if v.dtype.kind in "biuf" else v.astype(str))
                         for k, v in arrays.items() if v.ndim == 1 and v.size == n})
