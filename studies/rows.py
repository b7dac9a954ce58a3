"""Typed study rows and how they are written out: plain dicts (JSON lines) and text tables;
the loop's end state every study row records (:class:`EndState`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Self

if TYPE_CHECKING:
    from identification.criticism.criticism import Criticism

__all__ = ["EndState", "Row", "rows_table"]


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


@dataclass(frozen=True)
class EndState(Row):
    """Where a study's criticism loop ended: its last model, refitted, and that model's
    verdict and p-value (not only round 1's).

    Attributes
    ----------
    model
        The last model's equation, its coefficients refitted to the campaign.
    verdict
        Its criticism's verdict.
    p_value
        Its criticism's p-value.
    effects
        The effects the last model holds.
    """

    model: str
    verdict: str
    p_value: float
    effects: tuple[str, ...]

    @classmethod
    def of(cls, crit: Criticism) -> Self:
        """The end state of a loop whose last criticism is ``crit``."""
        model = crit.base.model
        return cls(model.equation(), str(crit.verdict), float(crit.p_value), tuple(model.effects))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        """An end state as :meth:`to_dict` wrote it."""
        return cls(data["model"], data["verdict"], data["p_value"], tuple(data["effects"]))


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
