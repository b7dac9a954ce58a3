"""Prediction of a record by a model: its simulation from the record's start, and its error.

``pm-joint predict --model MODEL RECORD --out FILE`` (:func:`predict_record`) simulates a
one-mode :class:`~identification.model.JointModel` or an N-mode
:class:`~identification.multimode.model.ModalModel` on the record's own time stamps:

* **Excitation.** The record's measured base excitation is replayed, interpolated between
  samples by a cubic spline (a base velocity is differentiated by the spline, a force is the
  equivalent base acceleration ``−g·F`` of a one-mode model); a free decay has none.
* **Sensors.** The model's modal coordinates reach the sensors through the mode shapes at
  them (the record's modes file, ``--mode-shapes``, else estimated from the record:
  :func:`~identification.measurements.modal_backbones.record_modal_filter`). An N-mode model's
  coordinate ``m`` is mode ``m``'s contribution at its reference sensor (where its shape is
  largest, as the backbones by mode read it), so the sensors see ``φ_sm / φ_ref(m),m``; a
  one-mode model's coordinate is the response sensor's (the backbones' response: the first
  ``--response`` column, the TRC centre point), so the sensors see ``φ_s / φ_response``.
  On one sensor every mode's coordinate is its contribution to that sensor.
* **Start.** A free decay whose step file marks its release or hit (TRC records) is
  simulated from there (:func:`~identification.sindy.modal_coordinates.decay_onset`); the
  model is at rest before it. Other records start at their first sample.
* **Initial state.** Least squares over the first :attr:`PredictSettings.fit_periods`
  periods of the lowest mode: each mode's free linear response (its frequency and decay
  rate) gives a first guess, refined by least squares on the model's own simulation of the
  window (nonlinear models, replayed excitation). The window stays inside the error's.
* **Output.** Every sensor in the record's quantity (derivatives of the simulated state,
  accelerations from the equations) and reference (the base motion added back where the
  record's response is absolute).
* **Error.** SSMLearn's normalised mean trajectory error (:func:`nmte`, docs/science.md §8).

A simulation that blows up (a response beyond :attr:`PredictSettings.divergence_factor`
times the record's largest) raises :class:`SimulationDiverged` (a ValueError: the CLI's
exit code 2 with one line).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline
from scipy.optimize import least_squares
from scipy.signal import detrend

from identification.artifacts import atomic_write_text
from identification.measurements.columns import ColumnLayout, open_records
from identification.measurements.modal_backbones import record_modal_filter
from identification.measurements.modes import Modes, read_modes
from identification.measurements.quantities import derivative_order
from identification.measurements.record import Record
from identification.measurements.trc_layout import CENTRE_POINT, N_PANEL_POINTS
from identification.model import PRESETS, JointModel
from identification.multimode.model import FORMAT as MODAL_FORMAT
from identification.multimode.model import ModalModel
from identification.sindy.modal_coordinates import decay_onset
from pm_joint.predict_equations import ModelEquations, model_equations

__all__ = [
    "PredictSettings",
    "Prediction",
    "SensorError",
    "SimulationDiverged",
    "load_model",
    "nmte",
    "predict_record",
    "write_prediction",
]

#: Format of the JSON file a prediction writes beside its CSV.
FORMAT = "pm-joint/prediction"
FORMAT_VERSION = 1


class SimulationDiverged(ValueError):
    """The model's simulation of the record blew up (e.g. a negative damping)."""


@dataclass(frozen=True)
class PredictSettings:
    """How a record is predicted.

    Attributes
    ----------
    fit_periods
        Periods of the lowest mode at the record's start its initial state is fitted on.
    embedding_periods
        Length of the delay embedding of a one-sensor record's error (periods of the
        lowest mode).
    rtol
        Relative tolerance of the integration (DOP853).
    divergence_factor
        A simulated response beyond this many times the record's largest has diverged.
    """

    fit_periods: float = 2.0
    embedding_periods: float = 2.0
    rtol: float = 1e-8
    divergence_factor: float = 100.0


class SensorError(NamedTuple):
    """One sensor's normalised mean trajectory error (a fraction; on its delay embedding)."""

    name: str
    nmte: float


@dataclass(frozen=True, eq=False)
class Prediction:
    """A model's prediction of a record.

    Attributes
    ----------
    time_s
        The record's time stamps (s).
    sensor_names
        One name per response sensor, as in the record (``point1``… for TRC records).
    quantity
        ``displacement``, ``velocity`` or ``acceleration`` (SI) of both arrays.
    relative
        Whether the responses are relative to the base (else absolute, as the record's).
    measured, predicted
        ``(n, S)`` the record's responses and the model's.
    nmte
        Normalised mean trajectory error (fraction): on the sensor vector, or on the delay
        embedding of the one sensor.
    sensors
        Each sensor's error alone (on its delay embedding).
    embedding_samples
        Samples of a one-sensor record's delay embedding (1: the sensor vector as it is).
    fit_window_s
        Start and end (s) of the window the initial state was fitted on.
    initial_displacement, initial_velocity
        ``(N,)`` fitted modal state at the record's start.
    sensor_shapes
        ``(S, N)`` what each modal coordinate gives at each sensor.
    excitation
        How the record drove the model: ``none`` or the replayed excitation's kind.
    """

    time_s: np.ndarray
    sensor_names: tuple[str, ...]
    quantity: str
    relative: bool
    measured: np.ndarray
    predicted: np.ndarray
    nmte: float
    sensors: tuple[SensorError, ...]
    embedding_samples: int
    fit_window_s: tuple[float, float]
    initial_displacement: np.ndarray
    initial_velocity: np.ndarray
    sensor_shapes: np.ndarray
    excitation: str

    def headline(self) -> str:
        """The one line the command prints: ``NMTE x.xx %``."""
        return f"NMTE {100 * self.nmte:.2f} %"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (everything but the time series)."""
        return {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "nmte": self.nmte,
            "nmte_percent": 100 * self.nmte,
            "per_sensor_nmte": {s.name: s.nmte for s in self.sensors},
            "quantity": self.quantity,
            "relative": self.relative,
            "sensors": list(self.sensor_names),
            "embedding_samples": self.embedding_samples,
            "fit_window_s": list(self.fit_window_s),
            "initial_modal_displacement": self.initial_displacement.tolist(),
            "initial_modal_velocity": self.initial_velocity.tolist(),
            "sensor_shapes": self.sensor_shapes.tolist(),
            "excitation": self.excitation,
        }


# ---------------------------------------------------------------------------
# The error


def _trajectory_norms(values: np.ndarray, embedding_samples: int) -> np.ndarray:
    """‖v(t)‖ of ``(n, S)`` values, each over ``embedding_samples`` delayed samples."""
    squares = np.concatenate([[0.0], np.cumsum(np.sum(values**2, axis=1))])
    m = embedding_samples
    return np.sqrt(np.maximum(squares[m:] - squares[:-m], 0.0))


def nmte(predicted: np.ndarray, measured: np.ndarray, embedding_samples: int = 1) -> float:
    """Normalised mean trajectory error: mean over time of ‖ŷ − y‖ over max over time of ‖y‖.

    Parameters
    ----------
    predicted, measured
        ``(n, S)`` (or ``(n,)``) responses.
    embedding_samples
        Length of the delay embedding: ``y(t)`` stands for ``(y(t), …, y(t + (M−1)Δt))``
        (1: the values as they are).
    """
    y = np.asarray(measured, dtype=float).reshape(len(measured), -1)
    error = np.asarray(predicted, dtype=float).reshape(y.shape) - y
    if not 1 <= embedding_samples <= y.shape[0]:
        raise ValueError(f"an embedding of {embedding_samples} samples in {y.shape[0]} samples")
    scale = _trajectory_norms(y, embedding_samples).max()
    if not scale > 0:
        raise ValueError("the measured response is zero throughout: no error can be normalised")
    return float(_trajectory_norms(error, embedding_samples).mean() / scale)


# ---------------------------------------------------------------------------
# Inputs


def load_model(source: str | os.PathLike | JointModel | ModalModel) -> JointModel | ModalModel:
    """A model from a JSON file (JointModel or versioned ModalModel), a preset name, or as is."""
    if isinstance(source, JointModel | ModalModel):
        return source
    path = Path(source)
    if not path.is_file():
        if str(source) in PRESETS:
            return JointModel.preset(str(source))
        raise ValueError(f"{source}: no model file, nor a preset ({', '.join(PRESETS)})")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a model JSON file ({exc})") from None
    if isinstance(data, dict) and data.get("format") == MODAL_FORMAT:
        return ModalModel.from_json(path)
    return JointModel.from_json(path)


def _read_record(source: str | os.PathLike, layout: ColumnLayout | None) -> Any:
    records = open_records(source, layout)
    if len(records) != 1:
        raise ValueError(f"{source}: predict takes one record, found {len(records)}")
    return records[0]


class _Signals(NamedTuple):
    """What the prediction compares and drives with."""

    time_s: np.ndarray
    names: tuple[str, ...]
    measured: np.ndarray
    response_index: int
    absolute: bool
    base: CubicSpline | None
    base_kind: str


def _signals(record: Any, model: JointModel | ModalModel) -> _Signals:
    t = np.asarray(record.time_s, dtype=float)
    trc = isinstance(record, Record)
    names = tuple(f"point{p}" for p in range(1, N_PANEL_POINTS + 1)) if trc else record.sensor_names
    base, kind = None, "none"
    if record.test != "free-decay" and record.excitation is not None:
        kind = record.excitation_kind
        if kind == "base-velocity":
            base = CubicSpline(t, record.excitation).derivative()
        elif kind == "base-acceleration":
            base = CubicSpline(t, record.excitation)
        else:
            if not isinstance(model, JointModel):
                raise ValueError(
                    f"{record.path or record.name}: a force-driven record needs a one-mode model "
                    "(an N-mode model has no driving-point shapes)"
                )
            gain = model.forcing_gain or record.forcing_gain
            base = CubicSpline(t, -gain * np.asarray(record.excitation))
    absolute = base is not None and not trc and not record.relative
    return _Signals(t, tuple(names), np.asarray(record.sensor_responses, dtype=float),
                    CENTRE_POINT - 1 if trc else 0, absolute, base, kind)  # fmt: skip


def _sensor_shapes(
    record: Any, model: JointModel | ModalModel, n_modes: int, signals: _Signals,
    mode_shapes: Modes | None,
) -> np.ndarray:  # fmt: skip
    """``(S, N)``: each modal coordinate's contribution at each sensor (module notes)."""
    n_sensors = signals.measured.shape[1]
    if n_sensors == 1:
        return np.ones((1, n_modes))
    shapes = record_modal_filter(record, n_modes, mode_shapes).shapes
    if isinstance(model, JointModel):
        at_response = shapes[signals.response_index, 0]
        if not abs(at_response) > 1e-3 * np.abs(shapes[:, 0]).max():
            raise ValueError(
                f"{record.path or record.name}: the first mode's shape is zero at the response "
                f"sensor {signals.names[signals.response_index]}: a one-mode model's coordinate "
                "cannot be carried to the other sensors"
            )
        return shapes / at_response
    reference = shapes[np.argmax(np.abs(shapes), axis=0), np.arange(n_modes)]
    return shapes / reference


def _base_motion(signals: _Signals, quantity: str) -> np.ndarray:
    """The base's motion in ``quantity`` at the samples (an absolute response carries it)."""
    acceleration = signals.base
    order = derivative_order(quantity)
    if order == 2:
        return acceleration(signals.time_s)
    velocity = detrend(acceleration.antiderivative()(signals.time_s))
    if order == 1:
        return velocity
    return detrend(CubicSpline(signals.time_s, velocity).antiderivative()(signals.time_s))


# ---------------------------------------------------------------------------
# Simulation


class _Simulator:
    """The model's response at the sensors over a span of the record's samples."""

    def __init__(self, eq: ModelEquations, signals: _Signals, shapes: np.ndarray, quantity: str,
                 settings: PredictSettings) -> None:  # fmt: skip
        self.eq, self.signals, self.shapes, self.settings = eq, signals, shapes, settings
        self.order = derivative_order(quantity)
        self.derivative = eq.derivative()
        omega = 2 * np.pi * eq.frequencies_hz.min()
        peak = np.abs(signals.measured).max() / omega**self.order
        #: Modal displacement scale of the record (m), for tolerances and the blow-up limit.
        self.scale = peak / max(np.abs(shapes).max(), 1e-12)
        self.limit = settings.divergence_factor * self.scale

    def states(self, y0: np.ndarray, n: int) -> np.ndarray:
        """``(state_size, n)`` states at the first ``n`` samples from ``y0``."""
        if self.signals.base is not None:
            return self._driven_states(y0, n)
        t = self.signals.time_s[:n]
        m = self.eq.n_modes
        w = 2 * np.pi * self.eq.frequencies_hz.max()
        atol = (
            self.settings.rtol
            * 1e-3
            * self.scale
            * np.concatenate([np.ones(m), np.full(m, w), np.ones(len(self.eq.sliders))])
        )

        def blow_up(_, state):
            return self.limit - np.abs(state[:m]).max()

        blow_up.terminal = True
        with np.errstate(over="ignore", invalid="ignore"):
            solution = solve_ivp(lambda _, y: self.derivative(y, 0.0), (t[0], t[-1]), y0,
                                 method="DOP853", t_eval=t, rtol=self.settings.rtol, atol=atol,
                                 events=blow_up)  # fmt: skip
        if solution.status != 0 or solution.y.shape[1] != n or not np.isfinite(solution.y).all():
            end = solution.t[-1] if solution.t.size else t[0]
            self._diverged(end, solution.message)
        return solution.y

    def _driven_states(self, y0: np.ndarray, n: int) -> np.ndarray:
        """Classic RK4 on the sample grid, each step cut so that ω_max·h ≤ 0.05: a measured
        excitation's noise makes an adaptive step shrink to nothing, and a fixed step that
        resolves the highest mode this finely errs far below a measurement's noise."""
        t = self.signals.time_s[:n]
        steps = max(1, int(np.ceil(2 * np.pi * self.eq.frequencies_hz.max() * np.diff(t).max()
                                   / _RK4_OMEGA_STEP)))  # fmt: skip
        fractions = np.arange(2 * steps + 1) / (2 * steps)
        times = (t[:-1, None] + np.diff(t)[:, None] * fractions).ravel()
        base = self.signals.base(times).reshape(n - 1, -1)
        f = self.derivative
        m = self.eq.n_modes
        out = np.empty((y0.size, n))
        out[:, 0] = y = np.asarray(y0, dtype=float)
        for i in range(n - 1):
            h = (t[i + 1] - t[i]) / steps
            for j in range(steps):
                a0, a1, a2 = base[i, 2 * j], base[i, 2 * j + 1], base[i, 2 * j + 2]
                k1 = f(y, a0)
                k2 = f(y + 0.5 * h * k1, a1)
                k3 = f(y + 0.5 * h * k2, a1)
                k4 = f(y + h * k3, a2)
                y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            if not np.abs(y[:m]).max() <= self.limit:
                self._diverged(t[i + 1], "")
            out[:, i + 1] = y
        return out

    def _diverged(self, time_s: float, why: str) -> None:
        raise SimulationDiverged(
            f"the simulation diverged at t = {time_s:.4g} s (modal displacement beyond "
            f"{self.limit:.3g}, {self.settings.divergence_factor:g} × the record's scale"
            + (f"; {why})" if why else ")")
        )

    def sensors(self, states: np.ndarray) -> np.ndarray:
        """``(n, S)`` the sensors' responses, in the record's quantity and reference."""
        m = self.eq.n_modes
        n = states.shape[1]
        if self.order == 0:
            modal = states[:m]
        elif self.order == 1:
            modal = states[m : 2 * m]
        else:
            base = 0.0 if self.signals.base is None else self.signals.base(self.signals.time_s[:n])
            modal = self.eq.accelerations(states, base)
        out = (self.shapes @ modal).T
        if self.signals.absolute:
            out = out + _base_motion(self.signals, _QUANTITIES[self.order])[:n, None]
        return out

    def response(self, y0: np.ndarray, n: int) -> np.ndarray:
        return self.sensors(self.states(y0, n))


_QUANTITIES = ("displacement", "velocity", "acceleration")
#: Largest ω·h of a step of the fixed-step integration of a driven record (RK4's phase error
#: per step is ~ (ωh)⁵/120).
_RK4_OMEGA_STEP = 0.05


def _free_response_guess(sim: _Simulator, n: int) -> np.ndarray:
    """``[η, η̇]`` at the start: least squares of each mode's free linear response."""
    eq, signals = sim.eq, sim.signals
    tau = signals.time_s[:n] - signals.time_s[0]
    y = signals.measured[:n]
    if signals.absolute:
        y = y - _base_motion(signals, _QUANTITIES[sim.order])[:n, None]
    omega = 2 * np.pi * eq.frequencies_hz
    sigma = eq.decay_rates
    damped = np.sqrt(np.maximum(omega**2 - sigma**2, (0.1 * omega) ** 2))
    s = -sigma + 1j * damped
    # y_s(τ) = Σ_m P_sm Re(C_m s_m^k e^{s_m τ}), C_m = a_m + i b_m
    w = s[None, :] ** sim.order * np.exp(np.outer(tau, s))  # (n, N)
    columns = np.concatenate([w.real, -w.imag], axis=1)  # (n, 2N)
    design = np.concatenate([sim.shapes, sim.shapes], axis=1)[:, None, :] * columns[None]
    coefficients = np.linalg.lstsq(design.reshape(-1, 2 * eq.n_modes), y.T.reshape(-1),
                                   rcond=None)[0]  # fmt: skip
    c = coefficients[: eq.n_modes] + 1j * coefficients[eq.n_modes :]
    return np.concatenate([c.real, (c * s).real])


def _initial_state(sim: _Simulator, n: int) -> np.ndarray:
    """The modal state at the start: the linear guess refined on the model's own simulation."""
    m = sim.eq.n_modes
    guess = _free_response_guess(sim, n)
    omega = 2 * np.pi * sim.eq.frequencies_hz
    scale = np.concatenate([np.full(m, sim.scale), sim.scale * omega])
    y = sim.signals.measured[:n]
    norm = np.abs(y).max()

    def residual(x: np.ndarray) -> np.ndarray:
        state = x * scale
        try:
            predicted = sim.response(sim.eq.initial_state(state[:m], state[m:]), n)
        except SimulationDiverged:
            return np.full(y.size, 1e3)
        return ((predicted - y) / norm).ravel()

    start = guess / scale
    fitted = least_squares(residual, start, x_scale=1.0, diff_step=1e-6, max_nfev=40 * m)
    best = fitted.x if fitted.cost <= 0.5 * np.sum(residual(start) ** 2) else start
    return best * scale


# ---------------------------------------------------------------------------
# The prediction


def predict_record(
    model: str | os.PathLike | JointModel | ModalModel,
    record: Any,
    *,
    layout: ColumnLayout | None = None,
    mode_shapes: str | os.PathLike | Modes | None = None,
    settings: PredictSettings | None = None,
) -> Prediction:
    """Simulate ``model`` from ``record``'s start and compare it with the record (module notes).

    Parameters
    ----------
    model
        A JointModel or ModalModel, its JSON file, or a JointModel preset's name.
    record
        A record (TRC :class:`Record` or column :class:`ColumnRecord`), or one record file
        read with ``layout``.
    layout
        How a record file's columns read (test type, response columns, quantity, …).
    mode_shapes
        Mode shapes at the sensors (a ``--mode-shapes`` file or :class:`Modes`); default
        the record's modes file, else estimated from the record.
    settings
        Fit window, embedding, tolerances.

    Raises
    ------
    SimulationDiverged
        The simulation blew up.
    ValueError
        Bad inputs (no such file, a record too short for the fit window, …).
    """
    settings = settings or PredictSettings()
    model = load_model(model)
    if isinstance(record, str | os.PathLike):
        record = _read_record(record, layout)
    if mode_shapes is not None and not isinstance(mode_shapes, Modes):
        decimal_comma = layout.decimal_comma if layout else None
        mode_shapes = read_modes(mode_shapes, decimal_comma=decimal_comma, points=None)
    eq = model_equations(model)
    signals = _signals(record, model)
    shapes = _sensor_shapes(record, model, eq.n_modes, signals, mode_shapes)
    quantity = record.quantity
    # A decay released (or hit) after a held or resting head starts at the release: before
    # it the model is at rest, and the hit is a force it does not carry.
    start = decay_onset(record, signals.measured)
    whole = signals
    signals = signals._replace(time_s=signals.time_s[start:], measured=signals.measured[start:])
    sim = _Simulator(eq, signals, shapes, quantity, settings)
    t = signals.time_s
    rate = (t.size - 1) / (t[-1] - t[0])
    period = 1.0 / eq.frequencies_hz.min()
    n_fit = round(settings.fit_periods * period * rate) + 1
    n_embed = max(1, round(settings.embedding_periods * period * rate))
    where = record.path or record.name
    if t.size < max(n_fit, n_embed) + 1:
        raise ValueError(
            f"{where}: {t.size} samples are fewer than the {settings.fit_periods:g} periods of "
            f"the lowest mode ({eq.frequencies_hz.min():.4g} Hz) the start is fitted on"
        )
    state = _initial_state(sim, n_fit)
    m = eq.n_modes
    predicted = np.zeros_like(whole.measured)
    predicted[start:] = sim.response(eq.initial_state(state[:m], state[m:]), t.size)
    measured = whole.measured
    largest = np.linalg.norm(measured, axis=1).max()
    if not np.linalg.norm(predicted, axis=1).max() <= settings.divergence_factor * largest:
        raise SimulationDiverged(
            f"the simulation diverged: its response exceeds {settings.divergence_factor:g} × "
            "the record's largest"
        )
    embedding = n_embed if measured.shape[1] == 1 else 1
    per_sensor = tuple(
        SensorError(name, nmte(predicted[:, [s]], measured[:, [s]], n_embed))
        for s, name in enumerate(signals.names)
    )
    return Prediction(
        time_s=whole.time_s, sensor_names=signals.names, quantity=quantity,
        relative=not signals.absolute, measured=measured, predicted=predicted,
        nmte=nmte(predicted, measured, embedding), sensors=per_sensor,
        embedding_samples=embedding, fit_window_s=(float(t[0]), float(t[n_fit - 1])),
        initial_displacement=state[:m], initial_velocity=state[m:], sensor_shapes=shapes,
        excitation=signals.base_kind,
    )  # fmt: skip


def write_prediction(prediction: Prediction, out: str | os.PathLike) -> tuple[Path, Path]:
    """Write the CSV (``time``, then one column per sensor) and ``OUT.json``; their paths."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    header = ",".join(["time", *prediction.sensor_names])
    rows = np.column_stack([prediction.time_s, prediction.predicted])
    lines = [header]
    lines += [",".join([f"{r[0]:.12g}", *(f"{v:.9e}" for v in r[1:])]) for r in rows]
    atomic_write_text(out, "\n".join(lines) + "\n")
    summary = Path(f"{out}.json")
    atomic_write_text(summary, json.dumps(prediction.to_dict(), indent=2) + "\n")
    return out, summary
