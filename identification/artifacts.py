"""Writing artifacts safely: atomic replacement, content hashes, provenance.

Every file pm-joint produces (models, datasets, surrogates, posteriors) goes
through these helpers so that an interrupted run never leaves a half-written
file under the final name, and so that a reader can tell a file that was
modified or corrupted after it was written (:func:`check_sha256`) and which
versions wrote it (:func:`versions`).

A hash over JSON content uses :func:`canonical_json`: sorted keys, no blanks,
floats as Python writes them (shortest round-trip form), so the hash of the
values read back from a file equals the hash written, whatever the file's
indentation.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import tempfile
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = [
    "DEFAULT_PACKAGES",
    "IntegrityError",
    "JsonDocument",
    "atomic_write_bytes",
    "atomic_write_text",
    "canonical_json",
    "check_sha256",
    "read_json_document",
    "sha256_bytes",
    "sha256_file",
    "sha256_json",
    "versions",
    "write_json_document",
]

#: Distributions whose versions every artifact records.
DEFAULT_PACKAGES = ("pm-joint", "numpy", "scipy")


class IntegrityError(ValueError):
    """An artifact's content does not match the hash recorded with it."""


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of ``data``."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 of a file's content, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def canonical_json(value: Any) -> bytes:
    """UTF-8 JSON of ``value`` with sorted keys and no blanks (the form that is hashed).

    NaN and infinities are refused (ValueError): they have no JSON form.
    """
    text = json.dumps(
        value, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
    )
    return text.encode("utf-8")


def sha256_json(value: Any) -> str:
    """Hex SHA-256 of :func:`canonical_json` of ``value``."""
    return sha256_bytes(canonical_json(value))


def check_sha256(
    expected: str, actual: str, source: str | Path, what: str = "the content", hint: str = ""
) -> None:
    """Raise :class:`IntegrityError` (a ValueError) unless the two hashes agree.

    Parameters
    ----------
    expected
        The hash recorded in the artifact.
    actual
        The hash of what was read.
    source
        The file, named in the message.
    what
        What was hashed (``"the terms"``, ``"the ONNX graph"``), named in the message.
    hint
        Appended to the message (what the user can do).
    """
    if expected != actual:
        raise IntegrityError(
            f"{source}: hash mismatch: {what} has SHA-256 {actual}, the file records "
            f"{expected}; it was modified or corrupted after it was written{hint}"
        )


def versions(*packages: str) -> dict[str, str | None]:
    """Versions of Python and of the installed distributions (None where not installed).

    With no arguments, those of :data:`DEFAULT_PACKAGES`; names are distribution
    names as pip knows them (``"pm-joint"``, ``"onnxruntime"``).
    """
    found: dict[str, str | None] = {"python": platform.python_version()}
    for package in packages or DEFAULT_PACKAGES:
        try:
            found[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            found[package] = None
    return found


def write_json_document(path: str | Path, data: dict[str, Any]) -> Path:
    """Write ``data`` as indented JSON (atomically), with the versions writing it."""
    data = {**data, "versions": versions()}
    return atomic_write_text(path, json.dumps(data, indent=2, ensure_ascii=False) + "\n")


def read_json_document(path: str | Path, what: str) -> Any:
    """The JSON content of ``path``; ValueError naming the file (and ``what`` it should hold)
    when it cannot be read or is not JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the {what} file ({exc.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None


class JsonDocument:
    """``to_json`` / ``from_json`` for a record that has ``to_dict`` and
    ``from_dict(data, source=...)`` (the models): the file is written atomically with the
    versions writing it, and a file that cannot be read is named in the error."""

    #: What the file holds, in error messages.
    document = "model"

    def to_json(self, path: str | Path) -> Path:
        """Write the record as JSON (atomically), with its hash and the versions writing it."""
        return write_json_document(path, self.to_dict())

    @staticmethod
    def check_content(data: dict[str, Any], record: Any, source: str, what: str) -> None:
        """Refuse ``record`` read from ``data`` when the hash ``data`` recorded (if any) is
        not that of its content (:class:`IntegrityError` naming ``source`` and ``what``)."""
        if "content_sha256" in data:
            check_sha256(
                data["content_sha256"],
                record.content_sha256,
                source,
                what,
                hint=" (remove 'content_sha256' to accept a deliberate edit)",
            )

    @classmethod
    def from_json(cls, path: str | Path) -> Any:
        """Read a record written by :meth:`to_json`; ValueError naming the file if it is bad."""
        return cls.from_dict(read_json_document(path, cls.document), source=str(path))
