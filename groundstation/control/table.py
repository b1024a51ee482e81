"""Numeric text tables as other tools write them: the delimiter, comments, a header.

Trajectory files come from spreadsheets and scripts, and each writes its own table:

* commas: CSV (pandas ``to_csv``, MATLAB ``writematrix``, numpy ``savetxt(delimiter=",")``,
  uav_trajectories);
* whitespace: numpy ``savetxt``'s default, MATLAB ``save -ascii`` (leading spaces), gnuplot
  data files;
* tabs: a spreadsheet's tab-separated export, MATLAB ``writematrix(..., "Delimiter", "tab")``;
* semicolons: a spreadsheet's CSV where the decimal mark is a comma (German, French
  locales): ``0,5;1,25;...``. There a number's decimal comma is read as a point.

The delimiter is the file's, taken from its first content line: the first of comma,
semicolon and tab found there, else runs of whitespace. Blank lines and lines whose first
non-blank character is ``#`` are comments, and so are rows of empty cells (``,,,``, as a
spreadsheet ends its export); empty cells at a row's end are dropped. The last comment
line before the first content line is kept as a possible header: numpy's
``savetxt(header=...)`` writes its header as a comment (``# t,x,y,z,yaw_deg``).
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass

__all__ = ["Table", "parse_number", "read_table"]

_DELIMITERS = (",", ";", "\t")
_DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d*,\d+(?:[eE][+-]?\d+)?\s*$")


@dataclass(frozen=True)
class Table:
    """The content of a delimited text table.

    rows : ``(line number, cells)`` of every content line, numbered from 1 as an editor
        numbers them; cells are the text between delimiters (not stripped)
    delimiter : ``","``, ``";"``, ``"\\t"`` or None (runs of whitespace)
    comment_header : the cells of the last comment line before the first content line
        (its ``#`` removed, split like the rows), or None if there is none
    """

    rows: list[tuple[int, list[str]]]
    delimiter: str | None
    comment_header: list[str] | None


def read_table(text: str) -> Table:
    """Split ``text`` into content rows (see the module doc). A text without content
    lines gives no rows."""
    lines = text.removeprefix("\ufeff").splitlines()  # the byte-order mark spreadsheets write
    first = next((ln for ln in lines if _is_content(ln)), "")
    delimiter = next((d for d in _DELIMITERS if d in first), None)
    rows: list[tuple[int, list[str]]] = []
    comment: str | None = None
    for lineno, line in enumerate(lines, start=1):
        if not _is_content(line):
            if not rows and line.strip():
                comment = line.strip().lstrip("#")
            continue
        cells = _split(line, delimiter)
        while cells and not cells[-1].strip():  # a spreadsheet pads short rows: ``1,2,,``
            cells.pop()
        if cells:
            rows.append((lineno, cells))
    header = None if comment is None else _split(comment, delimiter)
    return Table(rows, delimiter, header)


def parse_number(cell: str, delimiter: str | None) -> float:
    """The number in one cell; ValueError if it is none. In a semicolon-separated table
    a decimal comma (``1,25``, ``-0,5e-3``) is a decimal point."""
    try:
        return float(cell)
    except ValueError:
        if delimiter == ";" and _DECIMAL_COMMA.match(cell):
            return float(cell.replace(",", "."))
        raise


def _is_content(line: str) -> bool:
    stripped = line.strip()
    return bool(stripped) and not stripped.startswith("#")


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return next(csv.reader([line], delimiter=delimiter))
