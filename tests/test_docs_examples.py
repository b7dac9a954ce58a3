"""The README's and docs' examples run as printed, so they cannot drift.

A code block is runnable when the line before its fence (blank lines aside) is
``<!-- run -->``, or ``<!-- run slow -->`` for a block too long for ``make test``
(a page with one is marked ``slow``). Each page runs in a folder of its own that
holds a small campaign written by the project's own CLI (``pm-joint rig trc-like
--out campaign --assemblies 3``, the README's command): first its CLI blocks
(```` ```bash ````/```` ```console ````, ``pm-joint`` standing for ``python -m
pm_joint.cli``) in page order, then its Python blocks in page order, together in
one fresh interpreter. A block fails the test by a non-zero exit or a traceback;
what the Python blocks print must read as text: no numpy array repr, no line over
400 characters (a sentence of prose may run long; a result's repr that carries its
arrays runs to thousands), a screen's worth in all.

The same pages are held to the code in two cheap ways: every link of the README
and the docs points at a file of the repository, and ``docs/cli.md`` names every
subcommand and option the parser has.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")))
#: The README's campaign: three assemblies of the ``trc-like`` rig.
CAMPAIGN_COMMAND = ("rig", "trc-like", "--out", "campaign", "--assemblies", "3")
#: Longest line a printed result may have and still read as a summary.
MAX_LINE = 400
#: Most lines the examples of one page may print.
MAX_PRINTED_LINES = 60
#: Seconds one page may take (a hung sampler should fail, not stall CI).
PAGE_TIMEOUT_S = 1200

_MARKER = re.compile(r"^<!--\s*run(?P<slow>\s+slow)?\s*-->\s*$")
_FENCE = re.compile(r"^```(?P<lang>[\w-]*)")
_LINK = re.compile(r"\]\((?P<target>[^)\s]+)\)")


@dataclass(frozen=True)
class Block:
    """One runnable code block of a page."""

    page: Path
    line: int  # of the opening fence, 1-based
    language: str  # "python" or "bash"
    code: str
    slow: bool


def runnable_blocks(page: Path) -> list[Block]:
    """The blocks of ``page`` marked runnable, in page order."""
    lines = page.read_text(encoding="utf-8").splitlines()
    blocks, marked, i = [], None, 0
    while i < len(lines):
        text = lines[i]
        marker = _MARKER.match(text.strip())
        fence = _FENCE.match(text)
        if marker:
            marked = marker
        elif fence:
            start, i = i, i + 1
            while i < len(lines) and not lines[i].startswith("```"):
                i += 1
            if marked is not None:
                language = {"console": "bash", "sh": "bash"}.get(fence["lang"], fence["lang"])
                if language not in ("python", "bash"):
                    raise ValueError(f"{page.name}:{start + 1}: cannot run a {language!r} block")
                code = "\n".join(lines[start + 1 : i]) + "\n"
                blocks.append(Block(page, start + 1, language, code, bool(marked["slow"])))
            marked = None
        elif text.strip():
            marked = None  # a marker applies to the block right after it only
        i += 1
    return blocks


def _page_params() -> list:
    params = []
    for page in PAGES:
        blocks = runnable_blocks(page)
        if blocks:
            marks = [pytest.mark.slow] if any(b.slow for b in blocks) else []
            params.append(pytest.param(page, marks=marks, id=page.relative_to(ROOT).as_posix()))
    return params


def _env() -> dict[str, str]:
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


@pytest.fixture(scope="session")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The README's 3-assembly ``trc-like`` campaign, written once by the CLI."""
    folder = tmp_path_factory.mktemp("docs_campaign")
    done = subprocess.run(
        [sys.executable, "-m", "pm_joint.cli", *CAMPAIGN_COMMAND],
        cwd=folder, env=_env(), capture_output=True, text=True, timeout=PAGE_TIMEOUT_S,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return folder / "campaign"


def _page_folder(tmp_path: Path, campaign: Path) -> Path:
    """A folder whose ``campaign`` links the shared records, so what a page writes
    into the campaign (``backbones.csv``) stays its own."""
    own = tmp_path / "campaign"
    own.mkdir()
    for path in campaign.iterdir():
        (own / path.name).symlink_to(path)
    return tmp_path


def _run(args: list[str], cwd: Path, what: str) -> subprocess.CompletedProcess:
    done = subprocess.run(
        args, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=PAGE_TIMEOUT_S
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"{what} exited with {done.returncode}:\n{output[-4000:]}"
    assert "Traceback (most recent call last)" not in output, f"{what}:\n{output[-4000:]}"
    return done


def test_readme_marks_its_example_runnable():
    languages = [b.language for b in runnable_blocks(ROOT / "README.md")]
    assert "python" in languages


def test_marker_applies_to_the_next_block_only(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "<!-- run -->\n\n```python\nprint(1)\n```\n\n```python\nprint(2)\n```\n"
        "<!-- run slow -->\n```console\npm-joint effects\n```\n"
        "<!-- run -->\ntext between\n```python\nprint(3)\n```\n"
    )
    blocks = runnable_blocks(page)
    assert [(b.language, b.code, b.slow) for b in blocks] == [
        ("python", "print(1)\n", False),
        ("bash", "pm-joint effects\n", True),
    ]


@pytest.mark.parametrize("page", _page_params())
def test_page_examples_run(page: Path, tmp_path: Path, campaign: Path):
    folder = _page_folder(tmp_path, campaign)
    blocks = runnable_blocks(page)
    name = page.relative_to(ROOT).as_posix()
    for block in (b for b in blocks if b.language == "bash"):
        script = (
            "set -e -o pipefail\n"
            f'pm-joint() {{ "{sys.executable}" -m pm_joint.cli "$@"; }}\n{block.code}'
        )
        _run(["bash", "-c", script], folder, f"{name}:{block.line} (bash)")
    python = [b for b in blocks if b.language == "python"]
    if not python:
        return
    script = folder / "example.py"
    script.write_text("\n".join(b.code for b in python), encoding="utf-8")
    done = _run([sys.executable, str(script)], folder, f"{name}:{python[0].line} (python)")
    printed = done.stdout.splitlines()
    assert printed, f"{name}: the example printed nothing"
    long = [line for line in printed if len(line) > MAX_LINE]
    assert not long, f"{name}: printed lines over {MAX_LINE} characters: {long[0][:300]}…"
    assert "array(" not in done.stdout, f"{name}: printed a numpy array repr"
    assert len(printed) <= MAX_PRINTED_LINES, f"{name}: printed {len(printed)} lines"


def _targets(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.DOTALL)
    return [m["target"] for m in _LINK.finditer(text)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_stay_inside_the_repository(page: Path):
    for target in _targets(page):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # a web address or an anchor of the page itself
        path = (page.parent / target.split("#")[0]).resolve()
        assert path.is_relative_to(ROOT), f"{page.name} links outside the repository: {target}"
        assert path.exists(), f"{page.name} links to a missing file: {target}"


def test_cli_page_names_every_subcommand_and_option():
    import argparse

    from pm_joint.cli import build_parser

    page = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for command, subparser in sub.choices.items():
        assert f"## `pm-joint {command}`" in page, f"docs/cli.md lacks `pm-joint {command}`"
        for action in subparser._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help"):
                    assert f"`{option}" in page, f"docs/cli.md lacks {command} {option}"
