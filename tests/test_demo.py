"""``pm-joint demo``: every stage of the pipeline, end to end, and the report page it leaves.

Its own file (tests/test_cli.py holds the other subcommands) so that pytest-xdist's
``--dist loadfile`` can run it beside them.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pm_joint.cli import EXIT_NOT_CONVERGED
from pm_joint.html import missing_links

sys.path.insert(0, str(Path(__file__).parent))
from browser import assert_page_works, find_browser, require_browser

#: The demo at CI size: every stage of ``--size small`` on a smaller campaign (3 assemblies, 6
#: levels, as tests/test_cli_rig_campaign.py), fewer training curves and shorter chains. The
#: claims below are about the stages and the page, none about a figure's accuracy, so they are
#: the same at either size; ``--size small`` itself runs with ``-m slow``.
CI_SIZE = {"assemblies": 3, "n_levels": 6, "surrogate_curves": 40, "surrogate_epochs": 10,
           "draws": 200, "tune": 100, "hierarchical_draws": 60,
           "hierarchical_tune": 60}  # fmt: skip


def _run_demo(out: Path, size: dict | None = None) -> subprocess.CompletedProcess:
    """``pm-joint demo --size small`` in a fresh process, the small size replaced by ``size``."""
    script = (
        "import dataclasses, sys\n"
        "from pm_joint import cli, demo\n"
        f"demo.SIZES['small'] = dataclasses.replace(demo.SIZES['small'], **{size or {}!r})\n"
        "raise SystemExit(cli.main(sys.argv[1:]))\n"
    )
    argv = ["demo", "--size", "small", "--out", str(out)]
    return subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True,
                          timeout=1200)  # fmt: skip


def _check_demo(done: subprocess.CompletedProcess, out: Path) -> None:
    # Small draws need not converge: then the report is written and the exit says so.
    assert done.returncode in (0, EXIT_NOT_CONVERGED), done.stderr[-3000:]
    if done.returncode == EXIT_NOT_CONVERGED:
        assert "pm-joint demo: NOT CONVERGED" in done.stderr
    index = out / "index.html"
    assert missing_links(index) == []
    page = index.read_text()
    for section in ("SINDy identification", "Neural surrogate", "Stochastic updating",
                    "PDFs at low, mid and high amplitude", "Model criticism"):  # fmt: skip
        assert section in page
    # The criticism leads with each round's finding; the final model's state comes after.
    criticism = page[page.index('id="model-criticism"') :]
    assert criticism.index("Round 1 of ") < criticism.index("The final model")
    assert re.search(r"mean acceptance \d\.\d\d\.", page)  # was 0.26176666666666665
    # Each warning once (pytensor's object-mode notice came once per compiled function).
    warned = [line for line in done.stderr.splitlines() if line.startswith("pm-joint demo: ")]
    assert len(warned) == len(set(warned)), warned
    # The page in a real browser: every image loads, nothing logged as an error.
    if find_browser() or os.environ.get("CI") == "true":
        assert_page_works(index, require_browser())


@pytest.mark.heavy
def test_demo_runs_end_to_end_at_ci_size(tmp_path):
    _check_demo(_run_demo(tmp_path, CI_SIZE), tmp_path)


@pytest.mark.slow
def test_demo_runs_end_to_end_at_small_size(tmp_path):
    _check_demo(_run_demo(tmp_path), tmp_path)
