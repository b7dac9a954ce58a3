"""Column-layout files as named numeric columns: text tables with a header, MAT and HDF5.

Every format is read by its library, nothing parsed by hand:

* **Text** (``.csv``, ``.tsv``, ``.txt``, ``.dat``): one header line of column
  names, then rows; comma, semicolon, tab or blank separated; a decimal comma
  (German-locale exports: ``0,5;1,25``) is detected when the separator is not a
  comma, or stated (``decimal_comma=True``). Comment lines (``#``, ``%``) before
  the header are skipped. Read by the text-table reader the TRC files share
  (:mod:`identification.measurements.text_table`: pandas' C parser, block by
  block). A last line without a line break (a file cut short) is left out
  with a one-line warning.
* **MAT v5** (scipy.io.loadmat): numeric vectors as variables, fields of a
  struct (``data.time``), or the columns of a matrix named by a cell array of
  strings (``names``, ``labels``, ``channels`` or ``columns``).
* **MAT v7.3 and HDF5** (h5py): 1-D datasets (MATLAB's n×1 arrays included),
  by their path (``group/time``) or name, and the fields of a table (compound)
  dataset.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from identification.measurements.text_table import read_numbers, sniff

__all__ = ["COLUMN_EXTENSIONS", "HDF5_EXTENSIONS", "TEXT_EXTENSIONS", "read_table"]

TEXT_EXTENSIONS = (".csv", ".tsv", ".txt", ".dat")
HDF5_EXTENSIONS = (".h5", ".hdf5", ".he5")
#: File extensions read as column-layout records.
COLUMN_EXTENSIONS = (*TEXT_EXTENSIONS, ".mat", *HDF5_EXTENSIONS)
_NAME_LISTS = ("names", "labels", "channels", "columns")


def _text_table(path: Path, decimal_comma: bool | None) -> dict[str, np.ndarray]:
    layout = sniff(path, decimal_comma, labelled=True)
    assert layout.labels is not None
    table = read_numbers(path, layout, layout.columns, complete_lines=True)
    # One contiguous array per column, as the binary formats give them.
    return dict(zip(layout.labels, table.T.copy(), strict=True))


def _mat_table(path: Path) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    data = loadmat(path, squeeze_me=True, struct_as_record=False)
    columns: dict[str, np.ndarray] = {}
    names = next(
        ([str(n) for n in np.atleast_1d(data[k])] for k in data if k.lower() in _NAME_LISTS), None
    )

    def add(prefix: str, value) -> None:
        if hasattr(value, "_fieldnames"):  # a MATLAB struct
            for name in value._fieldnames:
                add(f"{prefix}/{name}", getattr(value, name))
            return
        array = np.asarray(value)
        if array.dtype.kind not in "fiub":
            return
        array = array.astype(float)
        if array.ndim <= 1:
            columns[prefix] = array
        elif array.ndim == 2 and names is not None and len(names) in array.shape:
            table = array if array.shape[1] == len(names) else array.T
            for j, name in enumerate(names):
                columns[name] = table[:, j]

    for key, value in data.items():
        if not key.startswith("__"):
            add(key, value)
    return columns


def _hdf5_table(path: Path) -> dict[str, np.ndarray]:
    import h5py

    columns: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as fh:
        for key, value in fh.attrs.items():
            if np.ndim(value) == 0 and np.asarray(value).dtype.kind in "fiu":
                columns[key] = np.asarray(value, dtype=float)

        def visit(name: str, node) -> None:
            if not isinstance(node, h5py.Dataset) or name.startswith("#"):
                return
            if node.dtype.names:  # a table: one column per field
                for field_name in node.dtype.names:
                    columns[f"{name}/{field_name}"] = np.asarray(node[field_name], float).ravel()
            elif node.dtype.kind in "fiu" and (node.ndim <= 1 or min(node.shape) == 1):
                columns[name] = np.asarray(node[()], dtype=float).ravel() if node.ndim else (
                    np.asarray(node[()], dtype=float))  # fmt: skip

        fh.visititems(visit)
    return columns


def read_table(path: str | Path, decimal_comma: bool | None = None) -> dict[str, np.ndarray]:
    """Every numeric column (and scalar) of a column-layout file, by name (see the module notes).

    Raises
    ------
    ValueError
        A missing file, an unknown extension, or content that is not a table of
        finite numbers (naming the row and column).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: file not found")
    suffix = path.suffix.lower()
    if suffix in TEXT_EXTENSIONS:
        return _text_table(path, decimal_comma)
    if suffix == ".mat":
        import h5py

        return _hdf5_table(path) if h5py.is_hdf5(path) else _mat_table(path)  # v7.3 is HDF5
    if suffix in HDF5_EXTENSIONS:
        return _hdf5_table(path)
    raise ValueError(
        f"{path}: unknown file type {suffix!r}; column layouts are {', '.join(COLUMN_EXTENSIONS)}"
    )
