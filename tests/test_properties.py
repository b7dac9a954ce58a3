"""Bad input, tried systematically: property-based tests (hypothesis).

Each property generates inputs, valid ones and ones broken in a chosen way
(truncated files, wrong column counts, non-numeric or non-finite cells,
repeated or reversed time stamps, empty or short hold phases, negative
amplitudes, mismatched parameter names, tampered JSON), and holds the outcome
to an independent expectation: the right numbers (a plain-Python reference
reader, the parameters of a synthetic signal, the original of a hashed file),
or a ValueError that names the file or field. Any other exception, or a wrong
number, fails the property.

Cases these properties once found are kept as explicit ``@example``s.

The number of cases each property ran is printed at the end of the module.
"""

from __future__ import annotations

import collections
import functools
import json
import math
import string
import sys
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from identification.artifacts import IntegrityError, sha256_bytes
from identification.effects import CATALOGUE
from identification.measurements import text_table
from identification.measurements.backbone import Backbone
from identification.measurements.extraction import extract_backbone
from identification.measurements.records import DATA_COLUMNS, Record, StepSchedule, read_record
from identification.model import JointModel
from pm_joint.distributions import BackboneDensity
from surrogates.runtime import MODEL_FILE, SIDECAR_FILE, SurrogateRuntime, SurrogateSpec

sys.path.insert(0, str(Path(__file__).parent))
from toy_surrogate import amplitude_frequency_weights, write_surrogate

#: Cases run per property, printed at the end of the module.
CASES: collections.Counter[str] = collections.Counter()
PROPERTY = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,  # the same cases on every run, so CI is stable
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def counted(test):
    """Count the cases a property runs (hypothesis calls the test once per case)."""

    @functools.wraps(test)
    def run(*args, **kwargs):
        CASES[test.__name__] += 1
        return test(*args, **kwargs)

    return run


@pytest.fixture(scope="module", autouse=True)
def _print_case_counts(request):
    yield
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    if reporter is None or capture is None or not CASES:
        return
    with capture.global_and_fixture_disabled():  # past pytest's capture of teardown output
        reporter.write_line(
            f"\nhypothesis: {sum(CASES.values())} cases over {len(CASES)} properties ("
            + ", ".join(f"{name} {n}" for name, n in sorted(CASES.items()))
            + ")"
        )


def _names_source(error: Exception, source: object) -> bool:
    return str(source) in str(error)


# ---------------------------------------------------------------------------
# Test records: the reader against a plain-Python reference reader

N_COLUMNS = len(DATA_COLUMNS)
LABELS = ["time", *(f"v{p:02d}" for p in range(1, 18)), "freq", "phase"]
FORMATS = {"repr": repr, "e6": "{:.6e}".format, "g9": "{:.9g}".format}
SEPARATORS = (" ", "\t", "  ", " \t ", ",", ", ")
CORRUPTIONS = (
    "none", "truncate", "drop_field", "extra_field", "bad_token", "non_finite",
    "empty_cell", "repeat_time", "reverse_time", "blank_line", "leading_blanks",
)  # fmt: skip
#: Steps that cover every generated record, so only the data file is on trial.
WIDE_STEPS = StepSchedule([-1e6, 1e6], [1.0, 1.0], source="wide steps")


def _strict_float(token: str) -> float:
    """The spec's number: what C's strtod reads (Python's float without its extras)."""
    if "_" in token or not token.isascii():
        raise ValueError(token)
    return float(token)


def _is_label(token: str) -> bool:
    try:
        complex(token.replace("i", "j") if token.endswith("i") else token)
    except ValueError:
        return True
    return False


def reference_read(text: str, comma: bool) -> dict:
    """What the layout spec says a data file holds, read line by line in plain Python.

    Returns ``{"ok": True, "data", "warned"}`` or ``{"ok": False, "kind", "row",
    "line"}`` for the first problem in file order (``row`` is the data row,
    ``line`` the file line; ``kind`` is "columns", "non-numeric", "non-finite",
    "time", "samples" or "empty").
    """
    *lines, tail = text.split("\n")
    warned = bool(tail.strip())  # a last line without a line break is left out
    rows, started, header_seen = [], False, False
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        tokens = [t.strip() for t in stripped.split(",")] if comma else stripped.split()
        if not started:
            if not stripped or stripped.startswith(("#", "%")):
                continue
            if not header_seen and all(_is_label(t) for t in tokens):
                header_seen = True
                continue
            started = True
        if stripped:
            rows.append((number, tokens))
    if not rows:
        return {"ok": False, "kind": "empty", "row": None, "line": None, "warned": warned}
    values = []
    for row, (number, tokens) in enumerate(rows, start=1):
        where = {"ok": False, "row": row, "line": number, "warned": warned}
        if len(tokens) != N_COLUMNS:
            return {**where, "kind": "columns"}
        parsed = []
        for token in tokens:
            try:
                parsed.append(_strict_float(token))
            except ValueError:
                return {**where, "kind": "non-numeric"}
            if not math.isfinite(parsed[-1]):
                return {**where, "kind": "non-finite"}
        values.append(parsed)
    data = np.array(values)
    if len(data) < 2:
        return {"ok": False, "kind": "samples", "row": None, "line": None, "warned": warned}
    for i in range(1, len(data)):
        if data[i, 0] <= data[i - 1, 0]:
            return {"ok": False, "kind": "time", "row": i + 1, "line": None, "warned": warned}
    return {"ok": True, "data": data, "warned": warned}


@st.composite
def trc_texts(draw):
    """A TRC data file as text, valid or broken in one of the ways of CORRUPTIONS."""
    n = draw(st.integers(2, 8))
    start = draw(st.floats(-100.0, 100.0))
    steps = draw(st.lists(st.floats(1e-4, 1.0), min_size=n - 1, max_size=n - 1))
    time = start + np.concatenate([[0.0], np.cumsum(steps)])
    values = draw(
        arrays(
            np.float64,
            (n, N_COLUMNS - 1),
            elements=st.floats(-1e6, 1e6, allow_subnormal=False),
        )
    )
    fmt = FORMATS[draw(st.sampled_from(sorted(FORMATS)))]
    rows = [[fmt(t), *(fmt(v) for v in row)] for t, row in zip(time, values, strict=True)]
    sep = draw(st.sampled_from(SEPARATORS))
    eol = draw(st.sampled_from(["\n", "\r\n"]))
    head = draw(st.sampled_from(["", "# comment", "labels", "% comment\n\nlabels"]))
    head = head.replace("labels", sep.join(LABELS))
    corruption = draw(st.sampled_from(CORRUPTIONS))
    row, col = draw(st.integers(0, n - 1)), draw(st.integers(0, N_COLUMNS - 1))
    if corruption == "drop_field":
        del rows[row][col]
    elif corruption == "extra_field":
        rows[row].insert(col, "1.0")
    elif corruption == "bad_token":
        alphabet = string.digits + "abexyzEj.+-_!?/:;@$"
        rows[row][col] = draw(st.text(alphabet, min_size=1, max_size=5))
    elif corruption == "non_finite":
        rows[row][col] = draw(st.sampled_from(["nan", "NaN", "-nan", "inf", "-Infinity", "+inf"]))
    elif corruption == "empty_cell":
        rows[row][col] = ""
    elif corruption == "repeat_time" and row > 0:
        rows[row][0] = rows[row - 1][0]
    elif corruption == "reverse_time" and row > 0:
        rows[row][0], rows[row - 1][0] = rows[row - 1][0], rows[row][0]
    elif corruption == "blank_line":
        rows.insert(row, [])
    elif corruption == "leading_blanks":
        rows[row][0] = "  " + rows[row][0]
    text = "".join(line + eol for line in ([head] if head else []) + [sep.join(r) for r in rows])
    if corruption == "truncate":
        text = text[: draw(st.integers(0, len(text) - 1))]
    return text, sep.strip() == ","


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("properties")


@PROPERTY
@given(case=trc_texts(), block_bytes=st.sampled_from([64, 300, 1 << 24]))
@counted
def test_record_reader_agrees_with_the_reference_or_names_the_problem(folder, case, block_bytes):
    """Blocks of 64 and 300 bytes cut every line and put block edges everywhere."""
    text, comma = case
    path = folder / "Config1_PRT_Assemb1.txt"
    path.write_bytes(text.encode())
    expected = reference_read(text, comma)
    with (
        mock.patch.object(text_table, "_BLOCK_BYTES", block_bytes),
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always")
        try:
            outcome = read_record(path, steps=WIDE_STEPS)
        except ValueError as error:
            outcome = error
    messages = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    assert all("no line break" in m and str(path) in m for m in messages), messages
    if expected["ok"]:
        assert isinstance(outcome, Record), outcome
        np.testing.assert_array_equal(outcome.data, expected["data"])
        assert bool(messages) == expected["warned"]
        return
    assert isinstance(outcome, ValueError), f"read {outcome!r}, expected {expected}"
    message = str(outcome)
    assert _names_source(outcome, path), message
    kind, row, line = expected["kind"], expected["row"], expected["line"]
    if kind in ("non-numeric", "non-finite") or (kind == "columns" and row > 1):
        assert f"row {row} (line {line})" in message and kind.split("-")[-1] in message, message
    elif kind == "time":
        assert "time stamps" in message and f"at row {row} " in message, message


# ---------------------------------------------------------------------------
# Backbone extraction: synthetic phase-resonance records with known answers

FS = 4000.0
N_PERIODS = 10
BACKBONE_CORRUPTIONS = (
    "none", "empty_hold", "short_hold", "frequency_not_positive", "sign_flip", "zero_response",
)  # fmt: skip
RAMP_S = 0.01


@st.composite
def synthetic_records(draw):
    """A record whose holds are pure sinusoids at phase resonance, and its true points.

    Per hold: base velocity ``B cos φ``, relative velocity ``A ω sin φ`` (lagging
    by 90°), frequency channel f; so amplitude A, frequency f and damping ratio
    ``B / (2 A ω)`` (module notes of :mod:`identification.measurements.extraction`).
    """
    n_holds = draw(st.integers(1, 3))
    holds = [
        {
            "f": draw(st.floats(50.0, 150.0)),
            "a": draw(st.floats(1e-6, 3e-3)),
            "b": draw(st.floats(1e-5, 1e-2)),
            "periods": draw(st.floats(N_PERIODS + 1.5, 2 * N_PERIODS)),
            "level": float(i + 1),
        }
        for i in range(n_holds)
    ]
    corruption = draw(st.sampled_from(BACKBONE_CORRUPTIONS))
    target = draw(st.integers(0, n_holds - 1))
    if corruption == "short_hold":
        holds[target]["periods"] = draw(st.floats(2.0, N_PERIODS - 1.0))
    time, columns, step_t, step_level, t = [], [], [0.0], [0.0], 0.0
    for i, hold in enumerate(holds):
        omega = 2 * np.pi * hold["f"]
        start = t + RAMP_S
        end = start + hold["periods"] / hold["f"]
        ts = np.arange(math.ceil(t * FS), math.floor(end * FS) + 1) / FS
        phase = omega * ts
        base = hold["b"] * np.cos(phase)
        relative = hold["a"] * omega * np.sin(phase)
        frequency = np.full_like(ts, hold["f"])
        if i == target and corruption == "frequency_not_positive":
            frequency[ts >= start] = draw(st.sampled_from([0.0, -hold["f"]]))
        elif i == target and corruption == "sign_flip":
            relative = -relative
        elif i == target and corruption == "zero_response":
            relative = np.zeros_like(ts)
        block = np.zeros((ts.size, N_COLUMNS))
        block[:, 0] = ts
        block[:, 1:16] = (base + relative)[:, None]  # every panel point moves with the centre
        block[:, 16:18] = base[:, None]
        block[:, 18] = frequency
        time.append(ts)
        columns.append(block)
        step_t += [start, end]
        step_level += [hold["level"]] * 2
        t = ts[-1] + 1 / FS
    data = np.concatenate(columns)
    if corruption == "empty_hold":  # a hold after the data ended
        step_t += [t + 1.0, t + 2.0]
        step_level += [99.0, 99.0]
    steps = StepSchedule(step_t, step_level, source="steps")
    record = Record(data, steps, "Config1_PRT_Assemb1")
    return record, holds, corruption, target


@PROPERTY
@given(case=synthetic_records(), strict=st.booleans())
@counted
def test_backbone_extraction_recovers_the_signal_or_names_the_hold(case, strict):
    record, holds, corruption, target = case
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        try:
            if corruption == "short_hold" and not strict:
                with pytest.warns(UserWarning, match="whole periods"):
                    outcome = extract_backbone(record, n_periods=N_PERIODS, strict=False)
            else:
                outcome = extract_backbone(record, n_periods=N_PERIODS, strict=strict)
        except ValueError as error:
            outcome = error
    flagged = corruption == "short_hold" and not strict  # documented: whole periods, a warning
    if corruption == "none" or flagged:
        assert isinstance(outcome, Backbone), outcome
        a, f, b = (np.array([h[k] for h in holds]) for k in ("a", "f", "b"))
        np.testing.assert_allclose(outcome.amplitude_m, a, rtol=1e-6)
        np.testing.assert_allclose(outcome.frequency_hz, f, rtol=1e-9)
        np.testing.assert_allclose(outcome.damping_ratio, b / (2 * a * 2 * np.pi * f), rtol=1e-6)
        np.testing.assert_allclose(outcome.phase_error_deg, 0.0, atol=1e-4)
        np.testing.assert_array_equal(outcome.excitation_level, [h["level"] for h in holds])
        return
    assert isinstance(outcome, ValueError), f"{corruption}: got {outcome!r}"
    level = 99.0 if corruption == "empty_hold" else holds[target]["level"]
    message = str(outcome)
    assert record.name in message and f"hold phase at level {level:g}" in message, message
    expected = {
        "empty_hold": "too few samples (0)",
        "short_hold": "fewer than n_periods",
        "frequency_not_positive": "not positive",
        "sign_flip": "negative power input",
        "zero_response": "no measurable response",
    }[corruption]
    assert expected in message, message


@PROPERTY
@given(
    values=arrays(np.float64, st.integers(1, 6), elements=st.floats(allow_subnormal=False)),
    field=st.sampled_from(["amplitude_m", "frequency_hz", "damping_ratio"]),
)
@counted
def test_backbone_refuses_negative_amplitudes_and_non_finite_values(values, field):
    good = {"amplitude_m": 1e-3, "frequency_hz": 100.0, "damping_ratio": 0.01}
    columns = {k: np.full(values.size, v) for k, v in good.items()}
    columns[field] = values
    bad = ~np.isfinite(values)
    if field == "amplitude_m":
        bad |= values < 0
    elif field == "frequency_hz":
        bad |= values <= 0
    try:
        curve = Backbone(**columns, label="curve")
    except ValueError as error:
        assert bad.any() and "curve" in str(error) and field in str(error), str(error)
        return
    assert not bad.any()
    np.testing.assert_array_equal(getattr(curve, field), values)


# ---------------------------------------------------------------------------
# Model JSON

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner),
    max_leaves=8,
)
EFFECT_NAMES = sorted(CATALOGUE)


@st.composite
def models(draw):
    effects = draw(st.lists(st.sampled_from(EFFECT_NAMES), min_size=1, max_size=4, unique=True))
    coefficients = st.floats(-1e9, 1e9, allow_subnormal=False)
    return JointModel({e: draw(coefficients) for e in effects}, name=draw(st.text(max_size=5)))


def _mutate(data, path, value):
    """A copy of a JSON tree with the item at ``path`` (keys/indices) replaced."""
    if not path:
        return value
    copy = list(data) if isinstance(data, list) else dict(data)
    copy[path[0]] = _mutate(copy[path[0]], path[1:], value)
    return copy


def _paths(data, prefix=()):
    """Every item's path in a JSON tree."""
    yield prefix
    items = (
        enumerate(data)
        if isinstance(data, list)
        else (data.items() if isinstance(data, dict) else ())
    )
    for key, value in items:
        yield from _paths(value, (*prefix, key))


#: A model's own document: the one generated JSON document that must load.
VALID_MODEL = JointModel({EFFECT_NAMES[0]: 2.5, EFFECT_NAMES[1]: -1.0}, name="valid")
VALID_DOCUMENT = json.loads(json.dumps(VALID_MODEL.to_dict()))


@PROPERTY
@given(document=json_values)
@example(document=VALID_DOCUMENT)
@counted
def test_any_json_document_is_a_model_or_a_named_error(folder, document):
    path = folder / "model.json"
    path.write_text(json.dumps(document))
    try:
        loaded = JointModel.from_json(path)
    except ValueError as error:
        assert document != VALID_DOCUMENT, f"valid input refused: {error}"
        assert _names_source(error, path), str(error)
        return
    if document == VALID_DOCUMENT:
        assert loaded == VALID_MODEL


@PROPERTY
@given(model=models(), data=st.data())
@counted
def test_a_hashed_model_file_loads_as_written_or_not_at_all(folder, model, data):
    """Any edit of a file that keeps its hash: the original terms, or a named error."""
    path = model.to_json(folder / "model.json")
    try:  # the file as written
        assert JointModel.from_json(path) == model
    except ValueError as error:
        raise AssertionError(f"valid input refused: {error}") from None
    original = json.loads(path.read_text())
    edit = data.draw(st.sampled_from(["replace", "truncate"]))
    if edit == "replace":
        where = data.draw(st.sampled_from(sorted(_paths(original), key=str)[1:]))  # not the root
        text = json.dumps(_mutate(original, where, data.draw(json_values)))
    else:
        full = path.read_text()
        text = full[: data.draw(st.integers(0, len(full) - 1))]
    path.write_text(text)
    try:
        loaded = JointModel.from_json(path)
    except ValueError as error:
        assert _names_source(error, path), str(error)
        return
    assert loaded == model  # the terms; a name or equation edit is harmless


@PROPERTY
@given(model=models(), data=st.data())
@counted
def test_a_changed_coefficient_is_a_hash_mismatch(folder, model, data):
    path = model.to_json(folder / "model.json")
    document = json.loads(path.read_text())
    term = data.draw(st.integers(0, len(model.terms) - 1))
    old = document["terms"][term]["coefficient"]
    new = data.draw(st.floats(-1e9, 1e9).filter(lambda v: v != old))
    document["terms"][term]["coefficient"] = new
    path.write_text(json.dumps(document))
    with pytest.raises(IntegrityError, match="hash mismatch") as caught:
        JointModel.from_json(path)
    assert _names_source(caught.value, path)


@PROPERTY
@given(
    model=models(),
    names=st.lists(st.sampled_from([*EFFECT_NAMES, "microslip.k_t", "nope", "x.y"]), max_size=4),
)
@counted
def test_parameter_names_must_be_the_models(model, names):
    values = {n: 1.0 for n in names}
    unknown = set(names) - set(model.parameter_names)
    try:
        changed = model.with_parameters(values)
    except ValueError as error:
        assert unknown and all(repr(n) in str(error) for n in unknown), str(error)
        return
    assert not unknown
    assert all(changed.parameters[n] == 1.0 for n in names)


# ---------------------------------------------------------------------------
# Surrogate sidecar and runtime

SPEC = SurrogateSpec(("k", "c"), [[0.9, 1.1], [1.0, 2.0]], np.linspace(1.0, 5.0, 5))
SPEC_KEYS = ("parameter_names", "bounds", "levels", "channels")


@pytest.fixture(scope="module")
def surrogate_folder(tmp_path_factory):
    weights = amplitude_frequency_weights(1e-4 * SPEC.levels, 100.0 + SPEC.levels)
    return write_surrogate(tmp_path_factory.mktemp("surrogate"), SPEC, weights)


def _spec_outcome(data):
    try:
        return SurrogateSpec.from_dict(data)
    except ValueError as error:
        return error


non_finite = st.sampled_from([math.nan, math.inf, -math.inf])
broken_numbers = non_finite | st.sampled_from([0.0, -1.0, 1e300])


@PROPERTY
@given(key=st.sampled_from(["bounds", "levels"]), index=st.integers(0, 9), value=broken_numbers)
@counted
def test_spec_numbers_are_checked(key, index, value):
    data = SPEC.to_dict()
    flat = np.array(data[key], dtype=float).ravel()
    flat[index % flat.size] = value
    data[key] = flat.reshape(np.shape(data[key])).tolist()
    outcome = _spec_outcome(data)
    bounds, levels = np.array(data["bounds"]), np.array(data["levels"])
    valid = (
        np.isfinite(bounds).all()
        and (bounds[:, 0] < bounds[:, 1]).all()
        and np.isfinite(levels).all()
        and (np.diff(levels) > 0).all()
    )
    assert isinstance(outcome, SurrogateSpec) == valid, outcome


#: The spec's own fields as JSON: a field set to its own value must load.
SPEC_JSON = json.loads(json.dumps(SPEC.to_dict()))


@PROPERTY
@given(key=st.sampled_from(SPEC_KEYS), value=json_values)
@example(key="parameter_names", value=5)
@example(key="bounds", value=SPEC_JSON["bounds"])
@counted
def test_spec_fields_of_any_json_type_are_a_spec_or_a_named_error(key, value):
    outcome = _spec_outcome({**SPEC.to_dict(), key: value})
    assert isinstance(outcome, SurrogateSpec | ValueError)
    if value == SPEC_JSON[key]:
        assert isinstance(outcome, SurrogateSpec), f"valid input refused: {outcome}"


@PROPERTY
@given(key=st.sampled_from(["format", "format_version", "onnx", *SPEC_KEYS]), value=json_values)
@example(key="onnx", value="surrogate.onnx")
@example(key="parameter_names", value=list(SPEC.parameter_names))
@counted
def test_sidecar_fields_of_any_json_type_load_or_name_the_file(surrogate_folder, key, value):
    sidecar = json.loads((surrogate_folder / SIDECAR_FILE).read_text())
    graph = (surrogate_folder / MODEL_FILE).read_bytes()
    try:
        SurrogateRuntime(graph, {**sidecar, key: value}, source="sidecar.json")
    except ValueError as error:
        assert value != sidecar[key], f"valid input refused: {error}"
        assert "sidecar.json" in str(error)


@PROPERTY
@given(data=st.data())
@counted
def test_truncated_or_altered_surrogate_files_are_refused(surrogate_folder, tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("altered")
    graph = (surrogate_folder / MODEL_FILE).read_bytes()
    sidecar = (surrogate_folder / SIDECAR_FILE).read_text()
    what = data.draw(st.sampled_from(["truncate sidecar", "truncate graph", "flip a graph byte"]))
    if what == "truncate sidecar":
        sidecar = sidecar[: data.draw(st.integers(0, len(sidecar.rstrip()) - 1))]
    elif what == "truncate graph":
        graph = graph[: data.draw(st.integers(0, len(graph) - 1))]
    else:
        at = data.draw(st.integers(0, len(graph) - 1))
        graph = graph[:at] + bytes([graph[at] ^ data.draw(st.integers(1, 255))]) + graph[at + 1 :]
    (folder / MODEL_FILE).write_bytes(graph)
    (folder / SIDECAR_FILE).write_text(sidecar)
    with pytest.raises(ValueError) as caught:
        SurrogateRuntime.load(folder)
    assert str(folder) in str(caught.value)
    if what != "truncate sidecar":
        assert "hash mismatch" in str(caught.value)


@PROPERTY
@given(graph=st.binary(min_size=1, max_size=64))
@example(graph=b"not an onnx graph")
@counted
def test_a_graph_onnxruntime_cannot_load_is_a_named_error(surrogate_folder, graph):
    sidecar = json.loads((surrogate_folder / SIDECAR_FILE).read_text())
    sidecar["onnx"]["sha256"] = sha256_bytes(graph)
    try:
        SurrogateRuntime(graph, sidecar, source="graph.onnx")
    except ValueError as error:
        assert "graph.onnx" in str(error)


# ---------------------------------------------------------------------------
# Likelihood inputs

LEVELS = np.array([1e-4, 2e-4, 4e-4, 8e-4])


@st.composite
def measured_matrices(draw):
    """Measured frequencies (n_curves, 4), with one chosen defect or none."""
    n = draw(st.integers(1, 8))
    centre = draw(st.floats(50.0, 150.0))
    # Distinct values: every level has a spread (a constant level is another property's case).
    spread = draw(arrays(np.float64, (n, LEVELS.size), elements=st.floats(-1.0, 1.0), unique=True))
    matrix = centre + spread
    levels = LEVELS.copy()
    defect = draw(st.sampled_from(["none", "non_finite", "columns", "levels_order", "levels_nan"]))
    if defect == "non_finite":
        matrix[draw(st.integers(0, n - 1)), draw(st.integers(0, 3))] = draw(non_finite)
    elif defect == "columns":
        matrix = matrix[:, : draw(st.integers(0, 3))]
    elif defect == "levels_order":
        levels = levels[::-1]
    elif defect == "levels_nan":
        levels[draw(st.integers(0, 3))] = math.nan
    return matrix, levels, defect


def _density_fit_outcome(matrix, levels, family):
    """The fitted density's log density at the measured curves, or the ValueError."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's fitting warns on small samples
        try:
            return BackboneDensity.fit(matrix, levels, family=family).logpdf(matrix)
        except ValueError as error:
            return error


@PROPERTY
@given(case=measured_matrices(), family=st.sampled_from(["copula", "mvn"]))
@counted
def test_density_fit_is_finite_or_a_value_error(case, family):
    """Held to the generated defect: a valid matrix of 3 curves or more is fitted, every
    defect refused (a fit that refused every input fails here)."""
    matrix, levels, defect = case
    outcome = _density_fit_outcome(matrix, levels, family)
    if defect == "none" and len(matrix) >= 3:
        assert not isinstance(outcome, ValueError), f"valid input refused: {outcome}"
        assert np.isfinite(outcome).all()
    else:
        assert isinstance(outcome, ValueError), f"{defect}, {len(matrix)} curves: fitted"


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the degenerate level's zero spread
@PROPERTY
@given(
    levels=arrays(np.float64, 4, elements=st.floats(-1e-3, 1e-3), unique=True).map(np.sort),
    constant=st.booleans(),
)
@example(levels=np.array([-1e-4, 1e-4, 2e-4, 3e-4]), constant=False)
@example(levels=LEVELS, constant=True)
@counted
def test_density_refuses_non_positive_levels_and_degenerate_levels(levels, constant):
    rng = np.random.default_rng(0)
    matrix = 100.0 + rng.standard_normal((6, 4))
    if constant:
        matrix[:, 1] = 100.0
    try:
        BackboneDensity.fit(matrix, levels, family="mvn").logpdf(matrix)
    except ValueError as error:
        assert not isinstance(error, np.linalg.LinAlgError), str(error)
        assert (levels <= 0).any() or constant
        return
    assert (levels > 0).all() and not constant


# ---------------------------------------------------------------------------
# The properties can fail: each, handed a reader that refuses every input, does


def _refuse(*args, source: str = "sidecar.json", **kwargs):
    raise ValueError(f"{source}: refused")


@pytest.fixture
def _cases_kept():
    """The printed case counts are those of the properties' own runs, not these."""
    kept = CASES.copy()
    yield
    CASES.clear()
    CASES.update(kept)


@pytest.mark.parametrize(
    ("prop", "owner", "method", "fixtures"),
    [
        (test_density_fit_is_finite_or_a_value_error, BackboneDensity, "fit", ()),
        (test_any_json_document_is_a_model_or_a_named_error, JointModel, "from_dict",
         ("folder",)),
        (test_a_hashed_model_file_loads_as_written_or_not_at_all, JointModel, "from_dict",
         ("folder",)),
        (test_spec_fields_of_any_json_type_are_a_spec_or_a_named_error, SurrogateSpec,
         "from_dict", ()),
        (test_sidecar_fields_of_any_json_type_load_or_name_the_file, SurrogateRuntime,
         "__init__", ("surrogate_folder",)),
    ],
    ids=lambda v: getattr(v, "__name__", ""),
)  # fmt: skip
def test_a_property_fails_on_a_reader_that_refuses_everything(
    prop, owner, method, fixtures, request, _cases_kept
):
    """ "A ValueError or the right answer" alone passes a reader that refuses every input:
    each of these properties also demands that its valid inputs are accepted."""
    arguments = {name: request.getfixturevalue(name) for name in fixtures}
    with (
        mock.patch.object(owner, method, _refuse),
        pytest.raises(AssertionError, match="valid input refused"),
    ):
        prop(**arguments)
