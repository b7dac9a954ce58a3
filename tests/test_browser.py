"""The report page in a real browser: headless Chromium opens a report made from a
small campaign and every image loads, nothing is logged as an error.

The smallest report with every kind of section the report writer makes without a
posterior: measured backbones and a criticism of two rounds (about half a minute).
The demo's page gets the same check in ``tests/test_cli.py``. Without Chromium the
tests skip and say why, except in CI (``CI=true``), where that is a failure.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from pm_joint.pipeline import criticize_campaign, run_report
from pm_joint.workspace import Workspace

sys.path.insert(0, str(Path(__file__).parent))
from browser import assert_page_works, open_page, require_browser


@pytest.fixture(scope="module")
def browser() -> str:
    return require_browser()


@pytest.fixture(scope="module")
def small_report(tmp_path_factory) -> Path:
    """Three noisy curves whose damping rises with amplitude, a linear model's criticism
    (one round adds the missing effect) and the report page of both."""
    folder = tmp_path_factory.mktemp("small_report")
    rng = np.random.default_rng(0)
    amplitude = np.geomspace(1e-5, 1e-3, 8)
    growth = np.sqrt(amplitude / amplitude[-1])
    curves = BackboneSet(
        Backbone(
            amplitude_m=amplitude,
            frequency_hz=f0 * (1 - 0.02 * growth) + 0.05 * rng.standard_normal(amplitude.size),
            damping_ratio=(0.004 + 0.004 * growth)
            * (1 + 0.03 * rng.standard_normal(amplitude.size)),
            label=f"Config1_PRT_Assemb{k}",
        )
        for k, f0 in enumerate([99.5, 100.0, 100.6], start=1)
    )
    csv = curves.to_csv(folder / "backbones.csv")
    omega = 2 * np.pi * 100.0
    model = JointModel({"linear_stiffness": omega**2, "viscous_damping": 2 * 0.005 * omega})
    criticize_campaign(csv, model, folder / "criticism", rounds=1, measured=curves)
    return run_report(Workspace(csv), folder / "report", criticism=folder / "criticism")


def test_the_report_page_loads_in_a_real_browser(browser, small_report):
    check = assert_page_works(small_report, browser)
    assert check.title == "pm-joint report"
    assert {Path(image.src).name for image in check.images} == {
        "backbones.png", "comparison.png", "signatures.png", "history.png"
    }  # fmt: skip


def test_the_browser_check_fails_on_a_broken_page(browser, small_report, tmp_path):
    """The check can fail: a missing image, a console error and a script error are seen."""
    page = tmp_path / "index.html"
    text = small_report.read_text(encoding="utf-8").replace(
        "</body>", '<img src="gone.png"><script>console.error("boom"); nope();</script></body>'
    )
    page.write_text(text.replace('src="', f'src="{small_report.parent.as_uri()}/'), "utf-8")
    check = open_page(page, browser)
    assert [Path(src).name for src in check.broken_images] == ["gone.png"]
    errors = "\n".join(check.errors)
    assert "ERR_FILE_NOT_FOUND" in errors and "console.error: boom" in errors
    assert "ReferenceError: nope is not defined" in errors
    with pytest.raises(AssertionError):
        assert_page_works(page, browser)
