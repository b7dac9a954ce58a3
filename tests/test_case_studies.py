"""Every case study runs as a script at small size and writes its figures."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

CASE_STUDIES = sorted((Path(__file__).parents[1] / "case_studies").glob("*.py"))


#: Case studies too long for the default suite (each stage keeps end-to-end coverage there).
SLOW = {
    "virtual_trc_benchmark",  # 180 s: SINDy's shape scan over the TRC-size records
    # 42 s; the CI-size hidden-effect acceptance (tests/test_acceptance_studies.py) runs
    # the same study's campaigns (studies.criticism_study), tests/test_criticism.py its plots
    "hidden_effect_study",
}


@pytest.mark.parametrize(
    "script",
    [pytest.param(s, marks=pytest.mark.slow) if s.stem in SLOW else s for s in CASE_STUDIES],
    ids=lambda p: p.stem,
)
def test_case_study_runs_at_small_size(script, tmp_path):
    env = {
        **os.environ,
        "PM_JOINT_SIZE": "small",
        "PM_JOINT_OUT": str(tmp_path),
        "MPLBACKEND": "Agg",
    }
    done = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=900,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-4000:]
    assert list(tmp_path.glob("*.png")), "the case study wrote no figure"
