"""Fitting JointModel parameters to backbones: recovery of known truths, the
linearised start, the likelihood, the scatter model, measured harmonics, errors."""

import dataclasses

import numpy as np
import pytest
from oscillators import measured_curve
from scipy import stats

from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.fitting.data import NOISE_FLOOR, fit_data, measurement_levels
from identification.fitting.least_squares import evaluate, fit_backbones
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel

W0 = 2 * np.pi * 101.0
K0 = W0**2
AMPS = 1e-3 * np.geomspace(0.05, 2.0, 8)


def linear(k_scale=1.0, zeta=0.003):
    return JointModel({"linear_stiffness": K0 * k_scale, "viscous_damping": 2 * zeta * W0})


def curves(models, amplitudes=AMPS, method="multi", noise_hz=0.0, noise_zeta=0.0, seed=0):
    """Harmonic-balance backbones of the models with Gaussian noise, as measured curves."""
    rng = np.random.default_rng(seed)
    out = []
    for i, m in enumerate(models):
        hb = harmonic_backbone(m, amplitudes, method=method)
        assert hb.converged.all()
        out.append(measured_curve(hb, rng, noise_hz, noise_zeta, f"c{i}"))
    return BackboneSet(out)


def test_duffing_population_is_recovered():
    """Three assemblies (±0.5 % stiffness) of a Duffing joint, multi-harmonic truth, noise."""
    truth = linear().with_effect("cubic_stiffness", 1.4e10)
    models = [truth.replace(linear_stiffness=K0 * s) for s in (0.995, 1.0, 1.005)]
    measured = curves(models, noise_hz=0.005, noise_zeta=2e-6)
    result = fit_backbones(linear().with_effect("cubic_stiffness", 0.0), measured)
    assert result.method == "single" and result.success
    assert result.model.coefficient("cubic_stiffness") == pytest.approx(1.4e10, rel=0.02)
    assert result.model.coefficient("linear_stiffness") == pytest.approx(K0, rel=1e-4)
    assert result.model.coefficient("viscous_damping") == pytest.approx(2 * 0.003 * W0, rel=0.01)
    # The mean residual (assembly offsets average out) is at the noise level.
    assert result.frequency_rmse_hz < 0.01 and result.damping_rmse < 2e-6
    # the likelihood counts the mean curve: levels × channels, not points
    assert result.n_parameters == 3 and result.n_residuals == 2 * AMPS.size


def test_linearised_start_is_exact_for_single_harmonic_data():
    """For data made by the single-harmonic balance the linear solve is the answer:
    every coefficient is recovered from a start of zeros, friction and ω-dependent
    damping terms included."""
    truth = linear().with_parameters({}).with_effect("cubic_stiffness", -3e9)
    truth = truth.with_effect("quadratic_damping", 4.0).with_effect("coulomb_friction", 0.2)
    measured = curves([truth], method="single")
    start = truth.with_parameters({e: 0.0 for e in truth.effects if e != "linear_stiffness"})
    result = fit_backbones(start, measured, method="single")
    for name, value in truth.parameters.items():
        assert result.model.parameters[name] == pytest.approx(value, rel=1e-6), name


def test_microslip_is_recovered_from_a_shape_scan():
    """A new Jenkins element (coefficient 0) starts from the scan of its slip amplitude."""
    k_t = 0.06 * K0
    truth = JointModel(
        {
            "linear_stiffness": K0 - k_t,
            "viscous_damping": 2 * 0.003 * W0,
            "microslip": {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * 2e-4},
        }
    )
    measured = curves([truth], amplitudes=1e-3 * np.geomspace(0.05, 2.0, 12), noise_hz=0.002)
    result = fit_backbones(linear().with_effect("microslip", 0.0), measured)
    _, k_fit, f_fit = result.model.microslip_arrays()
    assert result.model.coefficient("microslip") == 1.0  # fixed; k_t and F_s carry it
    assert k_fit == pytest.approx(k_t, rel=0.05)
    assert f_fit / k_fit == pytest.approx(2e-4, rel=0.05)
    assert result.model.linear_stiffness == pytest.approx(K0, rel=1e-4)


def with_harmonics(models, measured, noise=0.0, seed=0):
    """The curves with record-like harmonics from the multi-harmonic balance."""
    rng = np.random.default_rng(seed)
    out = []
    for m, curve in zip(models, measured, strict=True):
        hb = harmonic_backbone(m, curve.amplitude_m, method="multi")
        a = curve.amplitude_m[:, None]
        relative = (hb.harmonics_cos_m[:, 2:4] - 1j * hb.harmonics_sin_m[:, 2:4]) / a
        relative = relative + noise * (rng.standard_normal(relative.shape) + 0j)
        out.append(
            dataclasses.replace(
                curve, harmonics=relative, harmonic_standard_error=np.full(relative.shape, 1e-6)
            )
        )
    return BackboneSet(out)  # fmt: skip


def test_quadratic_stiffness_hides_in_the_backbone_and_shows_in_the_harmonics():
    """x² softens the backbone like −(5/6)k2²a²/ω0², which a refitted x³ absorbs
    (Δk3 = −(10/9)k2²/ω0² at leading order); the second harmonic separates them."""
    k2, k3 = -5e7, 1.4e10
    truth = linear().with_effect("cubic_stiffness", k3).with_effect("quadratic_stiffness", k2)
    small = 1e-3 * np.geomspace(0.02, 0.3, 8)  # leading order holds
    measured = curves([truth], amplitudes=small)
    cubic_only = fit_backbones(
        linear().with_effect("cubic_stiffness", k3), measured, method="multi"
    )
    expected_shift = -(10 / 9) * k2**2 / K0
    shift = cubic_only.model.coefficient("cubic_stiffness") - k3
    assert shift == pytest.approx(expected_shift, rel=0.03)
    # Over the full range, with the measured harmonics, x² is recovered from a start of 0.
    measured = with_harmonics([truth], curves([truth], noise_hz=0.002), noise=1e-5)
    start = linear().with_effect("cubic_stiffness", 1e10).with_effect("quadratic_stiffness", 0.0)
    result = fit_backbones(start, measured)
    assert result.method == "multi"
    assert result.model.coefficient("quadratic_stiffness") == pytest.approx(k2, rel=0.01)
    assert result.model.coefficient("cubic_stiffness") == pytest.approx(k3, rel=0.02)
    assert result.harmonic_rmse < 1e-4


def test_per_curve_fits_label_each_curve():
    scales = (0.99, 1.0, 1.012)
    models = [linear(s).with_effect("cubic_stiffness", 1e10 * s) for s in scales]
    measured = curves(models, method="single")
    results = fit_backbones(models[1], measured, per_curve=True, method="single")
    assert [r.data.labels for r in results] == [("c0",), ("c1",), ("c2",)]
    for s, r in zip(scales, results, strict=True):
        assert r.model.coefficient("linear_stiffness") == pytest.approx(K0 * s, rel=1e-8)
        assert r.model.coefficient("cubic_stiffness") == pytest.approx(1e10 * s, rel=1e-6)


def test_loglik_is_that_of_the_mean_curve_with_its_covariance():
    """The log-likelihood is the Gaussian density of the mean residual over curves at the
    levels, with the covariance of that mean (not of independent points); AIC and BIC
    count the fitted parameters; a channel weighted 0 leaves the likelihood."""
    models = [linear(s).with_effect("cubic_stiffness", 1e10) for s in (0.996, 1.004, 1.0)]
    measured = curves(models, noise_hz=0.01, noise_zeta=1e-5, seed=3)
    data = fit_data(measured)
    result = evaluate(linear(), data, free=["linear_stiffness", "viscous_damping"])
    # the curves share their amplitudes: the levels are those amplitudes
    np.testing.assert_allclose(data.levels_m, AMPS, rtol=1e-12)
    by_hand = (
        np.mean([np.column_stack([c.frequency_hz, c.damping_ratio]) for c in measured], axis=0)
        - result.predicted[: AMPS.size]
    )
    covariance = data.covariance.mean
    expected = stats.multivariate_normal(np.zeros(by_hand.size), covariance).logpdf(
        by_hand.reshape(-1)
    )
    assert result.loglik == pytest.approx(expected, rel=1e-10)
    n = by_hand.size
    assert result.n_residuals == n
    assert result.bic == pytest.approx(2 * np.log(n) - 2 * expected)
    assert result.aic == pytest.approx(4 - 2 * expected)
    # Frequency alone: half the entries, and its own covariance block.
    alone = evaluate(linear(), data, weights={"damping_ratio": 0.0})
    assert alone.n_residuals == n // 2


def test_covariance_of_the_mean_is_the_scatter_over_the_curve_count_plus_the_floors():
    """Three curves: the standard error of the mean curve is the between-curve scatter over
    √3 combined with the systematic floors; the scatter's variances lie within the
    curves' sample variances (shrunk toward the channel's median), the covariance does
    not depend on the model."""
    models = [linear(s, zeta=z) for s, z in ((0.99, 0.003), (1.0, 0.0031), (1.01, 0.0029))]
    measured = curves(models, method="single")
    data = fit_data(measured)
    mean, se = data.level_mean(data.values)
    np.testing.assert_allclose(mean[:, 0], np.mean([c.frequency_hz for c in measured], axis=0))
    covariance = data.covariance
    floors = np.tile([NOISE_FLOOR["frequency_hz"] ** 2, NOISE_FLOOR["damping_ratio"] ** 2],
                     AMPS.size)  # fmt: skip
    np.testing.assert_allclose(covariance.floor, floors)
    per_curve = np.diag(covariance.per_curve).reshape(AMPS.size, 2)
    np.testing.assert_allclose(se**2, per_curve / 3 + floors.reshape(AMPS.size, 2), rtol=1e-12)
    for j, values in enumerate(([c.frequency_hz for c in measured],
                                [c.damping_ratio for c in measured])):  # fmt: skip
        sample = np.var(values, axis=0, ddof=1)
        assert sample.min() * (1 - 1e-9) <= per_curve[:, j].min()
        assert per_curve[:, j].max() <= sample.max() * (1 + 1e-9)
    np.linalg.cholesky(covariance.mean)  # positive definite although 3 curves ≪ 16 entries
    before = data.whitened(evaluate(linear(), data).predicted)
    after = data.whitened(evaluate(linear(1.01), data).predicted)
    assert not np.allclose(before, after)  # one metric, two models


def test_bad_input_is_named():
    measured = curves([linear()], method="single")
    with pytest.raises(ValueError, match="unknown parameter"):
        fit_backbones(linear(), measured, free=["cubic_stiffness"])
    model = linear().with_effect("microslip", 1.0, k_t=1e4, F_s=1.0)
    with pytest.raises(ValueError, match="cannot all be free"):
        fit_backbones(model, measured, free=["microslip", "microslip.k_t", "microslip.F_s"])
    with pytest.raises(ValueError, match="unknown weight"):
        fit_backbones(linear(), measured, weights={"phase": 1.0})
    with pytest.raises(ValueError, match="shape_scan"):
        fit_backbones(linear(), measured, shape_scan={"viscous_damping": [1.0]})
    with pytest.raises(ValueError, match="unknown noise_floor"):
        fit_data(measured, noise_floor={"frequency": 0.1})
    with pytest.raises(ValueError, match="need method='multi'"):
        fit_backbones(linear(), with_harmonics([linear()], measured), method="single")


def test_too_sparse_data_is_refused():
    sparse = curves([linear(), linear(1.01)], amplitudes=np.array([1e-4, 1e-3]), method="single")
    with pytest.raises(ValueError, match="at least 3 are needed"):
        measurement_levels(sparse)


def test_harmonic_channels_come_from_the_backbones():
    """Curves carrying harmonics give the harmonic channels (cos = real, sin = −imag part,
    their standard errors in the spread); a curve without them has NaN there, and the
    backbones alone have the two backbone channels only."""
    models = [linear().with_effect("quadratic_stiffness", -5e7)] * 2
    measured = curves(models)
    with_h = with_harmonics(models[:1], measured[:1])
    mixed = BackboneSet([with_h[0], measured[1]])
    data = fit_data(mixed)
    assert data.channels[2:] == ("harmonic2_cos", "harmonic2_sin", "harmonic3_cos", "harmonic3_sin")
    first, second = data.curve == 0, data.curve == 1
    np.testing.assert_array_equal(data.values[first, 2], with_h[0].harmonics[:, 0].real)
    np.testing.assert_array_equal(data.values[first, 5], -with_h[0].harmonics[:, 1].imag)
    np.testing.assert_array_equal(data.standard_error[first, 2:], 1e-6)
    assert np.isnan(data.values[second, 2:]).all()
    assert fit_data(measured).channels == ("frequency_hz", "damping_ratio")


def test_each_point_is_driven_by_the_excitation_its_hold_measured():
    """lab-distorted: a linear-viscous truth driven by a base acceleration with 4 % of 2nd
    and 3 % of 3rd harmonic (the lab rig's time-domain engine). The response's 2nd harmonic
    (about 2ζ/3 of the excitation's) is explained by the linear model driven by each
    point's measured excitation, within a standard error at every point; driven by a pure
    sine it is 2–5 standard errors off, the harmonic RMSE ten times larger."""
    from identification.fitting.data import HARMONIC_CHANNELS
    from identification.measurements.extraction import extract_backbones
    from identification.rig import RIG_PRESETS, rig_for_preset

    rig = rig_for_preset("lab-distorted", levels=5, noise_m_s=1e-5)
    measured = extract_backbones(record for record, _ in rig.campaign(assemblies=2, seed=0))
    data = fit_data(measured)
    assert data.excitation_harmonics.shape == (10, 2)
    np.testing.assert_allclose(np.abs(data.excitation_harmonics).mean(axis=0), [0.04, 0.03],
                               rtol=0.15)  # fmt: skip
    fit = fit_backbones(RIG_PRESETS["lab-distorted"].base_model, data)
    assert fit.method == "multi"
    columns = [data.column(c) for c in HARMONIC_CHANNELS]
    se = data.standard_error[:, columns]
    z = (data.values[:, columns] - fit.predicted[:, columns]) / se
    assert np.abs(z).max() < 1.5
    pure = evaluate(fit.model, dataclasses.replace(data, excitation_harmonics=None))
    z_pure = (data.values[:, columns] - pure.predicted[:, columns]) / se
    assert np.abs(z_pure).max(axis=0)[1] > 4  # the 2nd harmonic's sine part
    assert pure.harmonic_rmse > 5 * fit.harmonic_rmse


def test_a_force_drives_the_model_as_its_equivalent_base_acceleration():
    """A force F per unit mass drives ẍ + f = F as the base acceleration −F does
    (ẍ + f = −a_base). Ratios are measured in each signal's own frame (its fundamental
    a real cosine), so the force's own ratios with ``excitation_kind="force"`` and those
    of the equivalent base acceleration −F with the default kind must give one
    prediction; the wrong kind must not (the even order flips)."""
    from identification.fitting.data import BACKBONE_CHANNELS, HARMONIC_CHANNELS
    from identification.fitting.prediction import predict_channels

    def own_frame(phasors):  # orders 1..3 → ratios of orders 2, 3 with the fundamental real
        turn = np.conj(phasors[0]) / abs(phasors[0])
        return phasors[1:] / abs(phasors[0]) * turn ** np.arange(2, phasors.size + 1)

    force = np.array([0.8 * np.exp(0.7j), 0.04 * np.exp(-1.1j), 0.03 * np.exp(2.0j)])
    model = JointModel({"linear_stiffness": K0, "viscous_damping": 2 * 0.003 * W0,
                        "quadratic_stiffness": -5e7, "cubic_stiffness": 1.4e10})  # fmt: skip
    a = 1e-3 * np.array([0.1, 0.5, 1.5])
    channels = BACKBONE_CHANNELS + HARMONIC_CHANNELS

    def predict(ratios, kind):
        return predict_channels(model, a, channels, method="multi", excitation_kind=kind,
                                excitation_harmonics=np.tile(ratios, (a.size, 1)))  # fmt: skip

    as_force = predict(own_frame(force), "force")
    as_base = predict(own_frame(-force), "base_acceleration")
    np.testing.assert_allclose(as_force, as_base, rtol=1e-8, atol=1e-12)
    wrong = predict(own_frame(force), "base_acceleration")
    # the forced 2nd harmonic (about 2ζ/3 of the 4 % in the force) changes sign
    assert np.abs(wrong - as_force)[:, 2:4].max() > 1e-4
    with pytest.raises(ValueError, match="excitation kind"):
        predict(own_frame(force), "base-velocity")


def test_a_refit_into_a_region_without_a_periodic_solution_is_a_named_outcome(monkeypatch):
    """Where the optimiser's steps reach parameters whose harmonic balance gives an absurd
    response (the README's example on a 3-assembly trc-like campaign met this in the
    model-term groups' refits: scipy's "array must not contain infs or NaNs"), the fit ends
    as :attr:`FitOutcome.NO_PERIODIC_SOLUTION` with the best model it could evaluate and
    says so in words, never a traceback; the fits that never go there are unchanged."""
    from identification.fitting import least_squares as ls

    truth = linear().with_effect("cubic_stiffness", 1.4e10)
    measured = curves([truth], noise_hz=0.005, noise_zeta=2e-6)
    start = linear().with_effect("cubic_stiffness", 0.0)
    plain = fit_backbones(start, measured)
    assert plain.outcome is ls.FitOutcome.CONVERGED and plain.solved
    real = ls.predict_channels
    first: dict[str, np.ndarray] = {}

    def blows_up(model, *args, parameters=None, **kwargs):
        """Every step away from the optimiser's start "converges" to an absurd response."""
        out = real(model, *args, parameters=parameters, **kwargs)
        if parameters is not None:
            rows = np.atleast_2d(np.asarray(parameters, dtype=float))
            start_row = first.setdefault("row", rows[0].copy())
            out[~np.all(rows == start_row, axis=1)] = 1e200
        return out

    monkeypatch.setattr(ls, "predict_channels", blows_up)
    result = fit_backbones(start, measured)
    assert result.outcome is ls.FitOutcome.NO_PERIODIC_SOLUTION and not result.solved
    assert not result.success and "periodic solution" in result.outcome_text
    assert np.isfinite(result.chi2)  # the best model it could evaluate, not the absurd one
    assert "no periodic solution" in repr(result)


def test_a_fit_result_prints_as_a_short_summary():
    """A FitResult's repr is a few lines (equation, outcome, χ², RMSE, the fitted
    parameters), not its arrays."""
    truth = linear().with_effect("cubic_stiffness", 1.4e10)
    result = fit_backbones(linear().with_effect("cubic_stiffness", 0.0), curves([truth]))
    text = repr(result)
    assert text.startswith("<FitResult ") and "converged" in text and "χ²" in text
    assert "cubic_stiffness=1.4" in text and "array(" not in text
    assert len(text.splitlines()) <= 4
