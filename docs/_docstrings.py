"""The package's docstrings are written to be read as plain text (``help()``, an editor): ``|x|`` is an
absolute value, tables are markdown, an indented line continues a thought. This turns such a docstring
into reStructuredText that reads the same in the API reference, without changing the source:

* ``|`` outside a table is escaped (no substitution references);
* a markdown table (``| a | b |`` rows, a ``|---|`` rule) becomes a ``list-table``;
* a change of indentation starts a new block (a blank line is inserted), except inside ``::`` literal
  blocks and doctest blocks;
* a section underline (a title followed by ``----``) becomes a bold paragraph.
"""

from __future__ import annotations

import re

RULE = re.compile(r"^\s*([-=~^])\1{2,}\s*$")
TABLE_ROW = re.compile(r"^\s*\|.*\|\s*$")
TABLE_RULE = re.compile(r"^\s*\|(\s*:?-{3,}:?\s*\|)+\s*$")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def _table(rows: list[str], indent: str) -> list[str]:
    header, body = _cells(rows[0]), [_cells(r) for r in rows[1:] if not TABLE_RULE.match(r)]
    out = ["", f"{indent}.. list-table::", f"{indent}   :header-rows: 1", ""]
    for row in [header, *body]:
        row = (row + [""] * len(header))[:len(header)]
        out.append(f"{indent}   * - {row[0] or ' '}")
        out += [f"{indent}     - {cell or ' '}" for cell in row[1:]]
    return out + [""]


def to_rst(lines: list[str]) -> list[str]:
    """The docstring ``lines`` (as autodoc hands them over, dedented) as reStructuredText lines."""
    out: list[str] = []
    literal_at = None           # indentation of the line that opened a ``::`` block
    previous = None             # indentation of the previous non-blank line
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            out.append("")
            i += 1
            continue
        ind = _indent(line)
        if literal_at is not None:
            if ind > literal_at:
                out.append(line)
                i += 1
                continue
            literal_at = None
        if TABLE_ROW.match(line) and i + 1 < len(lines) and TABLE_RULE.match(lines[i + 1]):
            j = i
            while j < len(lines) and TABLE_ROW.match(lines[j]):
                j += 1
            out += _table(lines[i:j], " " * ind)
            previous = None
            i = j
            continue
        if i + 1 < len(lines) and RULE.match(lines[i + 1]) and not RULE.match(line):
            out += ["", " " * ind + f"**{line.strip()}**", ""]
            previous = None
            i += 2
            continue
        if previous is not None and ind != previous and out and out[-1] != "" and not line.lstrip().startswith(">>>"):
            out.append("")
        text = line.replace("|", "\\|")
        out.append(text)
        previous = ind
        if line.rstrip().endswith("::"):
            literal_at = ind
        i += 1
    return out
