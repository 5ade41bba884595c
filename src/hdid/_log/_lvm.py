"""LabVIEW measurement files (``.lvm``) whose time is not written in every row.

LabVIEW's *Write To Measurement File* writes a file header and, per segment, a channel
header ending in ``***End_of_Header***`` that gives the first sample's time ``X0`` and the
sample step ``Delta_X`` [s]; then a row of names (``X_Value``, the channels, ``Comment``)
and the samples. With "X Value Columns: Empty time column" the ``X_Value`` cells are left
empty, and with ``X_Columns No`` there is no ``X_Value`` column at all: each sample's time
is then ``X0 + k·Delta_X``, which this module writes into the text before it is read
(:mod:`._layout` then takes the file header as a preamble, and each segment's repeated
names as a log written after the one before; a later segment's channel header becomes
blank lines, keeping the file's line numbers). A file whose rows carry their times is left
as it is.

A channel's unit is LabVIEW's ``Y_Unit_Label`` (one cell per channel, e.g. ``Deg``), not part
of its name (the DAQ task's ``Position``): where the name carries no unit of its own and the
label is a unit hdid knows, the name gets it in brackets (``Position [Deg]``), so that the
reader converts the channel as it would ``Position [deg]``. Other labels (``Volts``) are
left out, as before.
"""

from __future__ import annotations

from .. import _units

_MAGIC = "LabVIEW Measurement"
_END = "***End_of_Header***"


def _number(cell: str, comma: bool) -> float | None:
    try:
        return float(cell.replace(",", ".") if comma else cell)
    except ValueError:
        return None


def _known(label: str) -> bool:
    """Whether a ``Y_Unit_Label`` is a unit some column of hdid converts."""
    unit = _units._normal(label)
    return bool(unit) and unit != "-" and any(unit in table for table in _units.UNITS.values())


def _labelled(cells: list[str], labels: list[str]) -> list[str]:
    """The names row with each channel's known ``Y_Unit_Label`` in brackets after its name."""
    out, j = [], 0
    for cell in cells:
        name = cell.strip()
        if name in ("X_Value", "Comment") or not name:
            out.append(cell)
            continue
        label = labels[j].strip() if j < len(labels) else ""
        j += 1
        has_unit = _units.split(name)[1] is not None
        out.append(f"{name} [{label}]" if label and not has_unit and _known(label) else cell)
    return out


def fill_lvm_time(text: str) -> str:
    """The text of an ``.lvm`` file with every sample's time written (see the module)."""
    if not text.lstrip("\ufeff").startswith(_MAGIC):
        return text
    lines = text.split("\n")
    sep, comma = "\t", False
    x0 = dx = None
    names_next = False  # the line after a channel header's end is the names row
    fill = None  # "empty": X_Value cells to fill; "absent": a column to add
    k = 0
    seen_names = in_block = False
    labels: list[str] = []  # the segment's Y_Unit_Label cells, one per channel
    for i, line in enumerate(lines):
        cells = line.rstrip("\r").split(sep)
        head = cells[0].strip()
        if seen_names and head == "Channels":
            in_block, fill = True, None  # a later segment's channel header: not rows
        if in_block:
            lines[i] = ""
            in_block = head != _END
        if head == "Separator":
            sep = "," if len(cells) > 1 and cells[1].strip() == "Comma" else "\t"
        elif head == "Decimal_Separator":
            comma = len(cells) > 1 and cells[1].strip() == ","
        elif head == "X0" and len(cells) > 1:
            x0 = _number(cells[1].strip(), comma)
        elif head == "Delta_X" and len(cells) > 1:
            dx = _number(cells[1].strip(), comma)
        elif head == "Y_Unit_Label":
            labels = cells[1:]
        elif head == _END:
            names_next = (x0 is not None and dx is not None) or bool(labels)
            fill = None
        elif names_next and line.strip():
            names_next, seen_names = False, True
            k = 0
            if labels:
                cells = _labelled(cells, labels)
                lines[i] = sep.join(cells)
            if x0 is None or dx is None:
                pass  # the rows carry their times (or none to fill)
            elif head == "X_Value":
                fill = "empty"
            elif not any(c.strip() == "X_Value" for c in cells):
                fill = "absent"
                lines[i] = sep.join(["X_Value"] + cells)
        elif fill is not None and lines[i].strip():
            t = repr(x0 + k * dx)
            t = t.replace(".", ",") if comma else t
            if fill == "empty" and not head:
                lines[i] = sep.join([t] + cells[1:])
            elif fill == "absent":
                lines[i] = sep.join([t] + cells)
            k += 1
    return "\n".join(lines)
