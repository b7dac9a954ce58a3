"""The campaign workspace: each record read once, one density fit, one surrogate load.

Counted by wrapping the library's own entry points (``read_record``,
``BackboneDensity.fit``, ``SurrogateRuntime.load``) around real ``pm-joint``
runs on a rig campaign; the posterior report is checked against the density the
update sampled with, at levels that differ from the default ones (a report that
refitted the default density would refuse the trace).
"""

from __future__ import annotations

import json
import os
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import identification.measurements.discovery as records_module
from identification.measurements.backbone import BackboneSet
from pm_joint.cli import main
from pm_joint.distributions import BackboneDensity, amplitude_levels, level_marks
from pm_joint.inference import load_posterior, save_posterior, stored_density
from pm_joint.pipeline import campaign_backbones, label_records, write_rig_campaign
from pm_joint.workspace import RecordCache, Workspace
from surrogates.runtime import SurrogateRuntime, SurrogateSpec

sys.path.insert(0, str(Path(__file__).parent))
from toy_surrogate import amplitude_frequency_weights, write_surrogate

# Python-perform Ops (the surrogate) run in numba object mode; pytensor says so on compile.
pytestmark = pytest.mark.filterwarnings("ignore:Numba will use object mode:UserWarning")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    folder = tmp_path_factory.mktemp("workspace") / "campaign"
    write_rig_campaign("trc-like", folder, assemblies=3, n_levels=6, seed=2, progress=False)
    return folder


@pytest.fixture(scope="module")
def partial_surrogate(campaign, tmp_path_factory):
    """A linear toy surrogate that reaches only the lower 70 % of the measured shared range.

    With parameters (k, c) its backbone is ``c·a_ℓ`` (m) against ``k·f_ℓ`` (Hz);
    at the centre of its box, (1, 1), exactly the grid a_ℓ, f_ℓ below.
    """
    measured = Workspace(campaign, progress=False).backbones
    low, high = measured.common_range()
    amplitudes = np.geomspace(0.5 * low, low + 0.7 * (high - low), 12)
    frequencies = measured[0].frequency_at(amplitudes, extrapolate=True)
    spec = SurrogateSpec(("k", "c"), [[0.99, 1.01], [0.9, 1.1]], np.linspace(1.0, 5.0, 12))
    weights = amplitude_frequency_weights(amplitudes, frequencies)
    return write_surrogate(tmp_path_factory.mktemp("toy"), spec, weights)


class _Counts:
    """Calls of the wrapped library functions."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.reads: Counter[str] = Counter()
        self.fits = 0
        self.loads = 0
        read_record, fit, load = (
            records_module.read_record,
            BackboneDensity.fit.__func__,
            SurrogateRuntime.load.__func__,
        )

        def counted_read(path, *args, **kwargs):
            self.reads[Path(path).name] += 1
            return read_record(path, *args, **kwargs)

        def counted_fit(cls, *args, **kwargs):
            self.fits += 1
            return fit(cls, *args, **kwargs)

        def counted_load(cls, *args, **kwargs):
            self.loads += 1
            return load(cls, *args, **kwargs)

        monkeypatch.setattr(records_module, "read_record", counted_read)
        monkeypatch.setattr(BackboneDensity, "fit", classmethod(counted_fit))
        monkeypatch.setattr(SurrogateRuntime, "load", classmethod(counted_load))

    def reset(self) -> None:
        self.reads.clear()
        self.fits = self.loads = 0


@pytest.fixture(scope="module")
def updated(campaign, partial_surrogate, tmp_path_factory):
    """One `pm-joint update --report` from the records (no backbones.csv yet), counted."""
    (campaign / "backbones.csv").unlink(missing_ok=True)
    folder = tmp_path_factory.mktemp("update")
    posterior, report_dir = folder / "posterior.nc", folder / "report"
    argv = ["update", str(campaign), "--forward", "surrogate", "--surrogate"]
    argv += [str(partial_surrogate), "--out", str(posterior), "--report", str(report_dir)]
    argv += ["--sampler", "demetropolisz", "--draws", "150", "--tune", "100", "--chains", "1"]
    with pytest.MonkeyPatch.context() as monkeypatch:
        counts = _Counts(monkeypatch)
        # 150 draws of one chain do not converge: the posterior is written, exit code 3.
        assert main(argv) == 3
    return counts, posterior, report_dir


def test_one_update_reads_each_record_once_fits_once_and_loads_once(campaign, updated):
    counts, *_ = updated
    names = [p.name for p in Workspace(campaign).campaign.paths]
    assert dict(counts.reads) == dict.fromkeys(names, 1)  # extracted once, in one pass
    assert (counts.fits, counts.loads) == (1, 1)  # the report reused the update's density


def test_the_report_draws_the_density_the_update_sampled(campaign, updated, tmp_path, monkeypatch):
    _, posterior, report_dir = updated
    density = stored_density(load_posterior(posterior))
    measured = BackboneSet.from_csv(campaign / "backbones.csv")
    default = amplitude_levels(measured)
    # The surrogate reaches only part of the range: the likelihood's levels are not the default.
    assert density.amplitudes_m.size == default.size
    assert density.amplitudes_m[-1] < 0.9 * default[-1]
    observed = measured.frequency_matrix(density.amplitudes_m)
    np.testing.assert_allclose(density.observations, observed, rtol=1e-12)
    content = json.loads((report_dir / "report.json").read_text())
    for mark, index in level_marks(density.amplitudes_m).items():
        expected = 1e3 * density.amplitudes_m[index]
        assert content["level_pdfs"][mark]["amplitude_mm"] == pytest.approx(expected, rel=1e-12)
    # `pm-joint report` later: the stored density, the current CSV, nothing refitted or reread.
    counts = _Counts(monkeypatch)
    page = tmp_path / "page"
    assert main(["report", str(campaign), "--posterior", str(posterior), "--out", str(page)]) == 0
    assert (counts.fits, counts.loads, sum(counts.reads.values())) == (0, 0, 0)
    again = json.loads((page / "posterior" / "report.json").read_text())
    assert again["level_pdfs"] == content["level_pdfs"]


def test_a_posterior_without_its_density_warns_and_falls_back(campaign, updated, tmp_path, capsys):
    idata = load_posterior(updated[1])
    del idata.attrs["pm_joint_density"]  # as written before densities were stored
    old = save_posterior(idata, tmp_path / "old.nc")
    assert stored_density(load_posterior(old)) is None
    argv = ["report", str(campaign), "--posterior", str(old), "--out", str(tmp_path / "page")]
    with pytest.warns(UserWarning, match="no likelihood density is stored"):
        code = main(argv)
    # The old behaviour: a density at the default levels, which this trace was not sampled at.
    assert code == 2
    # the measured matrix kept with the draws (constant_data since population matching is a
    # potential) tells the refitted density apart
    assert "constant_data/backbone_measured" in capsys.readouterr().err


def test_backbones_csv_is_used_only_while_it_is_current(campaign, monkeypatch):
    counts = _Counts(monkeypatch)
    workspace = Workspace(campaign, progress=False)
    first = campaign_backbones(workspace)  # extracts and writes the CSV (and its PNG)
    assert (campaign / "backbones.png").is_file()
    assert sum(counts.reads.values()) == len(first)
    counts.reset()
    fresh = Workspace(campaign, progress=False)
    assert fresh.backbones.labels == first.labels and "read from" in fresh.backbones_origin
    assert sum(counts.reads.values()) == 0
    # A record rewritten after the CSV makes it stale: extracted again, every record once.
    record = Workspace(campaign).campaign.paths[1]
    before = record.stat()
    later = (campaign / "backbones.csv").stat().st_mtime + 1
    os.utime(record, (later, later))
    try:
        stale = Workspace(campaign, progress=False)
        np.testing.assert_array_equal(stale.backbones[1].frequency_hz, first[1].frequency_hz)
    finally:
        os.utime(record, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert "extracted from 3 records" in stale.backbones_origin
    assert set(counts.reads.values()) == {1} and len(counts.reads) == 3


def test_backbones_and_labels_share_one_read_of_each_record(campaign, monkeypatch):
    counts = _Counts(monkeypatch)
    from identification.model import JointModel

    model = JointModel(
        {"linear_stiffness": (2 * np.pi * 101) ** 2, "viscous_damping": 3.0,
         "cubic_stiffness": 3e10}
    )  # fmt: skip
    workspace = Workspace(campaign, model=model, progress=False)
    workspace.extract_backbones()
    labels = label_records(workspace)
    assert labels.shape == (3, 3) and np.all(np.isfinite(labels))
    assert set(counts.reads.values()) == {1} and len(counts.reads) == 3


def test_record_cache_keeps_records_while_there_is_room(campaign, monkeypatch):
    counts = _Counts(monkeypatch)
    none_kept = RecordCache(Workspace(campaign).campaign, max_bytes=0)
    first = none_kept[0]
    assert none_kept[0] is not first and none_kept.reads == {first.name: 2}
    room_for_one = RecordCache(Workspace(campaign).campaign, max_bytes=first.data.nbytes)
    for _ in range(2):  # two passes: the first record stays, the others are read again
        names = [record.name for record in room_for_one]
    assert room_for_one.reads == {names[0]: 1, names[1]: 2, names[2]: 2}
    assert room_for_one.kept_bytes == first.data.nbytes
    roomy = RecordCache(Workspace(campaign).campaign)
    assert [r.name for r in roomy] == names and roomy[1] is roomy[1]
    assert roomy.reads == dict.fromkeys(names, 1)
    assert sum(counts.reads.values()) == 2 + 5 + 3


def test_a_csv_source_has_backbones_but_no_records(campaign, tmp_path):
    csv = Workspace(campaign, progress=False).backbones.to_csv(tmp_path / "curves.csv")
    workspace = Workspace(csv)
    assert len(workspace.backbones) == 3 and workspace.backbones_origin == f"read from {csv}"
    with pytest.raises(ValueError, match="not a campaign"):
        _ = workspace.records
    with pytest.raises(ValueError, match="campaign folder not found"):
        _ = Workspace(tmp_path / "nowhere").records
    with pytest.raises(ValueError, match="no posterior given"):
        _ = workspace.posterior
