"""Typed study rows and how they are written out: plain dicts (JSON lines) and text tables."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

__all__ = ["Row", "rows_table"]


class Row:
    """A typed study row, written out as a plain dict (JSON lines, tables).

    ``_JSON_KEYS`` maps a field to its key in the written dict where the two differ (the
    files keep the keys they always had).
    """

    _JSON_KEYS: ClassVar[Mapping[str, str]] = {}

    def to_dict(self) -> dict[str, Any]:
        """The row as a dict of plain values (nested rows as dicts, sequences as lists)."""
        return {
            self._JSON_KEYS.get(f.name, f.name): _plain(getattr(self, f.name))
            for f in dataclasses.fields(self)  # type: ignore[arg-type]
        }


def _plain(value: Any) -> Any:
    if isinstance(value, Row):
        return value.to_dict()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def rows_table(rows: Sequence[Row | Mapping[str, Any]], columns: Sequence[str]) -> str:
    """Rows (typed, or dicts as written) as a fixed-width text table of the given columns."""

    def text(value: Any) -> str:
        if isinstance(value, float):
            return f"{value:.3g}"
        if isinstance(value, list | tuple):
            return ",".join(text(v) for v in value) or "—"
        return "—" if value is None else str(value)

    plain = [r.to_dict() if isinstance(r, Row) else r for r in rows]
    cells = [[text(r.get(c)) for c in columns] for r in plain]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(columns)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(columns, widths, strict=True))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(lines)
