"""Artifact integrity: atomic writes, content hashes, versions, safe loading.

Expectations are computed independently of :mod:`identification.artifacts`:
hashes with :mod:`hashlib` over JSON dumped here, versions from
:mod:`importlib.metadata` and the packages' own ``__version__``.

Elsewhere: the ONNX graph's hash in the surrogate sidecar is checked by
``tests/test_surrogates.py::test_tampered_graph_is_refused`` and, for any
truncation or changed byte, by ``tests/test_properties.py``.
"""

import hashlib
import json
import os
import platform
import re
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
import scipy

from identification.artifacts import (
    IntegrityError,
    atomic_write_text,
    canonical_json,
    sha256_file,
    sha256_json,
    versions,
)
from identification.model import JointModel
from identification.rig import GROUND_TRUTH_FILE, read_ground_truth

ROOT = Path(__file__).parents[1]


@pytest.fixture
def model():
    return JointModel.preset("pandey2025").with_effect("microslip", 1.0, k_t=3e4, F_s=0.8)


def _terms_hash(document: dict) -> str:
    """SHA-256 of the terms as sorted, blank-free JSON, computed here from scratch."""
    text = json.dumps(document["terms"], sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def test_model_file_carries_the_hash_of_its_terms_and_the_versions(tmp_path, model):
    document = json.loads(model.to_json(tmp_path / "model.json").read_text())
    assert document["content_sha256"] == _terms_hash(document) == model.content_sha256
    assert document["versions"] == {
        "python": platform.python_version(),
        "pm-joint": metadata.version("pm-joint"),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
    }


def test_a_changed_coefficient_is_refused_naming_the_file(tmp_path, model):
    path = model.to_json(tmp_path / "model.json")
    document = json.loads(path.read_text())
    document["terms"][0]["coefficient"] *= 1.001
    path.write_text(json.dumps(document, indent=2))
    with pytest.raises(IntegrityError, match="hash mismatch") as caught:
        JointModel.from_json(path)
    assert isinstance(caught.value, ValueError) and str(path) in str(caught.value)
    assert "remove 'content_sha256' to accept a deliberate edit" in str(caught.value)
    del document["content_sha256"]  # the user's deliberate edit
    path.write_text(json.dumps(document))
    assert JointModel.from_json(path).coefficient("linear_stiffness") == pytest.approx(
        1.001 * model.coefficient("linear_stiffness")
    )


def test_files_written_before_the_hash_existed_still_load(tmp_path, model):
    document = model.to_dict()
    del document["content_sha256"]
    path = tmp_path / "old.json"
    path.write_text(json.dumps(document))
    assert JointModel.from_json(path) == model


def test_the_hash_does_not_depend_on_layout_or_key_order(tmp_path, model):
    document = json.loads(model.to_json(tmp_path / "model.json").read_text())
    reordered = {key: document[key] for key in reversed(list(document))}
    reordered["terms"] = [dict(reversed(list(t.items()))) for t in document["terms"]]
    path = tmp_path / "compact.json"
    path.write_text(json.dumps(reordered, separators=(",", ":")))
    assert JointModel.from_json(path) == model


def test_a_newer_format_version_is_refused(tmp_path, model):
    path = tmp_path / "future.json"
    path.write_text(json.dumps({**model.to_dict(), "version": 99}))
    with pytest.raises(ValueError, match="format version 99"):
        JointModel.from_json(path)


def test_a_tampered_ground_truth_model_is_refused(tmp_path, model):
    entry = {"model": model.to_dict(), "shaker_gain": 10.0, "noise_m_s": 1e-4, "seed": [0, 1, 1]}
    entry["model"]["terms"][1]["coefficient"] = 0.0
    document = {"format": "pm-joint/rig-ground-truth", "records": {"Config1_PRT_Assemb1": entry}}
    (tmp_path / GROUND_TRUTH_FILE).write_text(json.dumps(document))
    with pytest.raises(IntegrityError, match="hash mismatch") as caught:
        read_ground_truth(tmp_path)
    assert str(tmp_path / GROUND_TRUTH_FILE) in str(caught.value)


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path, model, monkeypatch):
    path = model.to_json(tmp_path / "model.json")
    before = path.read_bytes()

    def crash(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        JointModel({"linear_stiffness": 1.0}).to_json(path)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_text(tmp_path / "new.json", "{}")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]


def test_canonical_json_and_its_hash():
    assert canonical_json({"b": [1.5, "μ"], "a": None}) == '{"a":null,"b":[1.5,"μ"]}'.encode()
    assert sha256_json({"a": 1, "b": 2}) == sha256_json({"b": 2, "a": 1})
    assert sha256_json([0.1]) == hashlib.sha256(b"[0.1]").hexdigest()
    with pytest.raises(ValueError, match="not JSON compliant"):
        canonical_json({"x": float("nan")})


def test_versions_of_named_and_missing_distributions():
    found = versions("numpy", "no-such-distribution-pm-joint")
    assert found == {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "no-such-distribution-pm-joint": None,
    }


def test_sha256_file_reads_in_chunks(tmp_path):
    data = os.urandom(3 << 20)  # three of its 1 MiB chunks
    path = tmp_path / "blob"
    path.write_bytes(data)
    assert sha256_file(path) == hashlib.sha256(data).hexdigest()


#: Calls that can run code from a file: (pattern, what makes them safe).
UNSAFE_LOADS = {
    r"\bpickle\.loads?\(": None,
    r"\bcloudpickle\.loads?\(": None,
    r"\bdill\.loads?\(": None,
    r"\bjoblib\.load\(": None,
    r"\bshelve\.open\(": None,
    r"\bmarshal\.loads?\(": None,
    r"\byaml\.load\(": r"Loader\s*=\s*yaml\.SafeLoader",
    r"\btorch\.load\(": r"weights_only\s*=\s*True",
    r"\bnp\.load\(": r"^(?!.*allow_pickle\s*=\s*True)",
}


def test_no_file_is_unpickled_by_the_package():
    """User-received files must never be loaded with pickle (or torch.load without weights_only).

    Tests may pickle their own objects in memory (picklability checks), so only
    the installed packages, scripts and case studies are scanned.
    """
    found = []
    for folder in ("identification", "surrogates", "pm_joint", "bench", "case_studies"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                for pattern, safe in UNSAFE_LOADS.items():
                    if re.search(pattern, line) and not (safe and re.search(safe, line)):
                        found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "unsafe deserialisation:\n" + "\n".join(found)


def test_posterior_file_carries_a_hash_and_versions_checked_on_load(tmp_path):
    from arviz_base import from_dict

    from pm_joint.inference import load_posterior, save_posterior

    rng = np.random.default_rng(0)
    idata = from_dict({"posterior": {"k": rng.normal(size=(2, 50)), "c": rng.normal(size=(2, 50))}})
    path = save_posterior(idata, tmp_path / "posterior.nc", metadata={"sampler": "test"})
    loaded = load_posterior(path)
    np.testing.assert_array_equal(loaded.posterior["k"].values, idata.posterior["k"].values)
    assert "pymc" in json.loads(loaded.attrs["pm_joint_versions"])

    tampered = loaded.copy(deep=True)
    tampered["posterior"]["k"] = tampered["posterior"]["k"] + 1.0
    tampered.to_netcdf(tmp_path / "tampered.nc")  # keeps the recorded hash
    with pytest.raises(ValueError, match=r"tampered\.nc: hash mismatch"):
        load_posterior(tmp_path / "tampered.nc")
