"""Numeric text tables: the one reader of the TRC files and the column-layout text files.

A table is optional comment lines (``#`` or ``%``) and blank lines, a header
line, then rows of numbers. Without labels (the TRC files) the header is
optional: one line of non-numeric labels is skipped. With labels (the column
files) the first line is the header, and it names the columns.

The delimiter is a semicolon, a tab, a comma or runs of blanks. A header
line says which (the first of ``;``, tab, ``,`` in it, else blanks). Without
one, the first data line does: ``;`` where splitting on it reads better (all
fields numbers, or more of them) than the comma/blank reading; else ``,``
where the line has one, unless only blanks split it into numbers, written
with decimal commas (``0,5 1,25``); else blanks (tabs among them). A decimal
comma (German-locale exports: ``0,5;1,25``) is detected where the delimiter
is not a comma and a field of the first data line is written with one, or
stated (``decimal_comma=True``).

Reading is block by block (pandas' C parser, about 16 MB of text at a time)
into one array, so a long file needs little memory beyond its numbers. A last
line without a line break (a file cut short mid-line, whose last number may
be cut too) is left out with a warning. Anything else that is not a table of
finite numbers (a missing or extra column, a non-numeric, NaN or infinite
cell) is a ValueError naming the file, row and line.
"""

from __future__ import annotations

import io
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pandas as pd

__all__ = ["TextLayout", "format_table", "parse_complex", "read_numbers", "sniff"]

COMMENT = ("#", "%")
_BOM = b"\xef\xbb\xbf"
#: Text handed to the C parser at a time: large next to a call's overhead, small
#: next to a long record.
_BLOCK_BYTES = 1 << 24
#: Delimiters a header line may name, in the order they are looked for.
_HEADER_DELIMITERS = (";", "\t", ",")


@dataclass(frozen=True)
class TextLayout:
    """Where the numbers of a text table start and how they are written.

    Attributes
    ----------
    skip
        Lines before the first data line (comments, blanks, the header).
    offset
        Byte at which the first data line starts.
    delimiter
        ``;``, ``\\t`` or ``,``; None for runs of blanks.
    decimal_comma
        Numbers are written ``0,5`` for 0.5.
    columns
        Fields of the first data line, or the labels' count when there are labels.
    labels
        Column names from the header, for tables whose header names them.
    fast_sep
        The separator the C parser tries first: one blank character where the
        first data line has exactly one between fields, which the parser splits
        on about a third faster than on runs of blanks (``\\s+``).
    """

    skip: int
    offset: int
    delimiter: str | None
    decimal_comma: bool
    columns: int
    labels: tuple[str, ...] | None = None
    fast_sep: str = r"\s+"

    @property
    def sep(self) -> str:
        """The separator as the C parser takes it."""
        return self.delimiter or r"\s+"

    def split(self, line: str) -> list[str]:
        """The fields of a line, blanks around them stripped."""
        text = line.strip()
        if self.delimiter is None:
            return text.split()
        return [f.strip() for f in text.split(self.delimiter)]

    def number(self, token: str) -> float:
        """A cell as the C parser reads it (ValueError when it does not)."""
        if self.decimal_comma:
            if "." in token:
                raise ValueError(token)
            token = token.replace(",", ".")
        # Python's float() also takes "1_000" and non-ASCII digits, which the C parser
        # refuses; refusing them here too keeps the diagnosis in step with the parser.
        if "_" in token or not token.isascii():
            raise ValueError(token)
        return float(token)

    def complex_number(self, token: str) -> complex:
        """A cell that may be complex (``a+bj`` or MATLAB's ``a+bi``)."""
        return parse_complex(token.replace(",", ".") if self.decimal_comma else token)


def parse_complex(token: str) -> complex:
    """A real or complex number; MATLAB writes the imaginary unit as i, Python as j."""
    return complex(token[:-1] + "j" if token.endswith("i") else token)


def _is_plain_number(token: str) -> bool:
    try:
        parse_complex(token)  # real numbers parse too
    except ValueError:
        return False
    return True


def _has_decimal_comma(token: str) -> bool:
    """Whether ``token`` is a (real or complex) number written with decimal commas."""
    return (
        "," in token
        and "." not in token
        and re.search(r",(?!\d)", token) is None
        and _is_plain_number(token.replace(",", "."))
    )


def _is_number(token: str) -> bool:
    return _is_plain_number(token) or _has_decimal_comma(token)


def _numbers(fields: list[str]) -> tuple[bool, int]:
    """Whether all fields are numbers, and how many are: the better split scores higher."""
    found = sum(map(_is_number, fields))
    return found == len(fields), found


def _fields(text: str, delimiter: str | None) -> list[str]:
    return text.split() if delimiter is None else [f.strip() for f in text.split(delimiter)]


def _data_delimiter(text: str) -> str | None:
    """The delimiter of a first data line (no header names it): see the module notes."""
    usual = "," if "," in text else None
    if ";" in text and _numbers(_fields(text, ";")) > _numbers(_fields(text, usual)):
        return ";"
    if usual == ",":
        # Blank-separated numbers with decimal commas (``0,5 1,25``; a one-column
        # ``1,5+0,5j``) are no comma-separated numbers.
        blanks = text.split()
        if (
            not all(map(_is_number, _fields(text, ",")))
            and all(map(_is_number, blanks))
            and any(map(_has_decimal_comma, blanks))
        ):
            return None
    return usual


def _fast_sep(line: str, delimiter: str | None) -> str:
    if delimiter is not None:
        return delimiter
    text = line.rstrip("\r\n")
    blanks = set(re.findall(r"\s", text))
    if len(blanks) == 1 and text == text.strip() and 2 * min(blanks) not in text:
        return min(blanks)
    return r"\s+"


def _labels(line: str, delimiter: str | None) -> tuple[str, ...]:
    """Column names of a header line, unquoted as pandas does (``a``, ``a.1`` for twice)."""
    frame = pd.read_csv(io.StringIO(line), sep=delimiter or r"\s+", nrows=0,
                        skipinitialspace=True, engine="c")  # fmt: skip
    return tuple(str(name) for name in frame.columns)


def sniff(path: Path, decimal_comma: bool | None = None, labelled: bool = False) -> TextLayout:
    """Find the first data line: delimiter, decimal separator, lines and bytes to skip.

    Parameters
    ----------
    path
        The text file.
    decimal_comma
        Numbers written ``0,5``; None detects it from the first data line.
    labelled
        The first line (after comments and blanks) is a header of column names.
    """
    header: str | None = None
    offset = 0
    with open(path, "rb") as fh:
        for skip, raw in enumerate(fh):
            if skip == 0 and raw.startswith(_BOM):
                raw = raw[len(_BOM) :]
                offset = len(_BOM)
            line = raw.decode("utf-8", errors="replace")
            text = line.strip()
            if text and not text.startswith(COMMENT):
                fields = _fields(text, _data_delimiter(text))
                if header is None and (labelled or not any(map(_is_number, fields))):
                    header = line  # one line of column labels
                else:
                    return _layout(path, skip, offset, line, header, decimal_comma, labelled)
            offset += len(raw)
    if labelled:
        raise ValueError(f"{path}: needs a header line of column names and rows of numbers")
    raise ValueError(f"{path}: no numeric data found (the file is empty or only has headers)")


def _layout(
    path: Path,
    skip: int,
    offset: int,
    line: str,
    header: str | None,
    decimal_comma: bool | None,
    labelled: bool,
) -> TextLayout:
    text = line.strip()
    if labelled:
        assert header is not None
        delimiter = next((d for d in _HEADER_DELIMITERS if d in header), None)
    else:
        delimiter = _data_delimiter(text)
    fields = _fields(text, delimiter)
    if decimal_comma is None:
        decimal_comma = delimiter != "," and any(map(_has_decimal_comma, fields))
    if decimal_comma and delimiter == ",":
        raise ValueError(f"{path}: a decimal comma cannot go with comma-separated columns")
    labels = _labels(header, delimiter) if labelled and header is not None else None
    return TextLayout(
        skip=skip,
        offset=offset,
        delimiter=delimiter,
        decimal_comma=decimal_comma,
        columns=len(labels) if labels is not None else len(fields),
        labels=labels,
        fast_sep=_fast_sep(line, delimiter),
    )


def _text_blocks(fh: BinaryIO, stop: int) -> Iterator[bytes]:
    """Blocks of about ``_BLOCK_BYTES`` of whole lines, from ``fh``'s position to ``stop``."""
    while chunk := fh.read(min(_BLOCK_BYTES, stop - fh.tell())):
        cut = chunk.rfind(b"\n") + 1
        while cut == 0 and (more := fh.read(min(_BLOCK_BYTES, stop - fh.tell()))):
            chunk += more  # a line longer than a block
            cut = chunk.rfind(b"\n") + 1
        if 0 < cut < len(chunk):
            fh.seek(cut - len(chunk), io.SEEK_CUR)  # the partial last line starts the next block
            chunk = chunk[:cut]
        yield chunk


def _complete_lines_end(fh: BinaryIO, size: int) -> int:
    """Byte after the file's last line break (0 when it has none)."""
    end = size
    while end > 0:
        step = min(end, 1 << 16)
        fh.seek(end - step)
        cut = fh.read(step).rfind(b"\n")
        if cut >= 0:
            return end - step + cut + 1
        end -= step
    return 0


def _parse_block(text: bytes, layout: TextLayout, columns: int) -> np.ndarray | None:
    """The rows of a block of lines, or None when they are not ``columns`` finite numbers."""
    for sep in dict.fromkeys((layout.fast_sep, layout.sep)):
        try:
            block = pd.read_csv(
                io.BytesIO(text),
                sep=sep,
                header=None,
                dtype=np.float64,
                engine="c",
                decimal="," if layout.decimal_comma else ".",
                na_filter=False,  # "nan" and empty cells are errors, not missing values
                skipinitialspace=layout.delimiter is not None,
                skip_blank_lines=True,
            ).to_numpy()
        except pd.errors.EmptyDataError:  # blank lines only
            return np.empty((0, columns))
        except (ValueError, pd.errors.ParserError):
            continue
        if block.shape[1] == columns and np.isfinite(block).all():
            return block
    return None


def _diagnose(path: Path, start: int, row: int, layout: TextLayout, columns: int) -> str:
    """Name the first bad row from byte ``start`` on (a slow scan, only on the error path).

    ``row`` is the number of data rows before ``start``. A labelled column is
    named by its label, with a hint where a decimal comma would explain it.
    """
    with open(path, "rb") as fh:
        fh.seek(layout.offset)
        line = layout.skip + 1
        while fh.tell() < start:
            line += fh.read(min(start - fh.tell(), _BLOCK_BYTES)).count(b"\n")
        for number, raw in enumerate(fh, start=line):
            fields = layout.split(raw.decode("utf-8", errors="replace"))
            if fields in ([], [""]):
                continue
            row += 1
            where = f"row {row} (line {number})"
            if len(fields) != columns:
                return f"{where} has {len(fields)} columns, expected {columns}"
            for col, token in enumerate(fields, start=1):
                try:
                    value = layout.number(token)
                except ValueError:
                    value = None
                if layout.labels is None:
                    if value is None:
                        return f"{where}, column {col}: non-numeric value {token!r}"
                    if not np.isfinite(value):
                        return f"{where}, column {col}: non-finite value {token!r}"
                    continue
                label = layout.labels[col - 1]
                if value is None:
                    hint = " (a decimal comma? pass --decimal-comma)" if "," in token else ""
                    return f"{where}, column {label!r}: not a number: {token!r}{hint}"
                if not np.isfinite(value):
                    return f"{where}, column {label!r}: not finite: {token!r}"
    return f"unreadable content after line {line}"


def read_numbers(
    path: Path,
    layout: TextLayout,
    columns: int,
    progress: bool = False,
    complete_lines: bool = False,
) -> np.ndarray:
    """Read the rows of a table of ``columns`` numbers, block by block, into one array.

    pandas' C parser reads each block of about 16 MB of text; the rows go into
    one array grown in place, so the peak memory is the table plus one block's
    worth, whatever the file's size. A block that fails is scanned line by line
    to name the offending row, so errors stay precise without slowing the
    normal path. With ``complete_lines``, a last line without a line break (a
    file cut short mid-line, whose last number may be cut too) is left out
    with a warning.

    Returns
    -------
    The (rows, columns) table, read-only.
    """
    size = path.stat().st_size
    table = np.empty((0, columns))  # owns its memory: resized in place, never copied
    rows = 0
    with open(path, "rb") as fh, _progress_bar(path, size, layout.offset, progress) as bar:
        stop = size
        if complete_lines:
            stop = max(_complete_lines_end(fh, size), layout.offset)
            fh.seek(stop)
            if fh.read(1 << 20).strip():
                warnings.warn(
                    f"{path}: the last line has no line break, so the file may have been cut "
                    "short mid-line; that line is left out",
                    stacklevel=4,
                )
        fh.seek(layout.offset)
        start = layout.offset
        for text in _text_blocks(fh, stop):
            block = _parse_block(text, layout, columns)
            if block is None:
                raise ValueError(f"{path}: {_diagnose(path, start, rows, layout, columns)}")
            if rows + len(block) > len(table):
                # The rows still to come at this block's bytes per row, and a little more.
                estimate = 1.02 * (stop - fh.tell()) * len(block) / len(text)
                shape = (rows + len(block) + int(estimate) + 1, columns)
                if rows:
                    table.resize(shape, refcheck=False)
                else:  # np.empty: resize would first fill it with zeros
                    table = np.empty(shape)
            table[rows : rows + len(block)] = block
            rows += len(block)
            start += len(text)
            bar.update(len(text))
    if rows == 0:
        raise ValueError(f"{path}: no complete line of numeric data")
    table.resize((rows, columns), refcheck=False)
    table.setflags(write=False)  # owned by nobody else: records keep it without a copy
    return table


def _progress_bar(path: Path, size: int, done: int, show: bool):
    """A tqdm bar over the file's bytes (disabled unless ``show``)."""
    from tqdm.auto import tqdm  # optional at import time

    return tqdm(
        total=size, initial=done, unit="B", unit_scale=True, desc=path.name, disable=not show
    )


def format_table(table: np.ndarray, comma: bool, precision: int) -> str:
    """A table as text the reader reads back: ``%.{precision}e``, comma or blank separated.

    The first column (time) keeps at least 10 digits so that 10 kHz stamps stay
    distinct in long records.
    """
    formats = [f"%.{max(precision, 9)}e"] + [f"%.{precision}e"] * (table.shape[1] - 1)
    buffer = io.StringIO()
    np.savetxt(buffer, table, fmt=formats, delimiter="," if comma else " ")
    return buffer.getvalue()
