"""What the refinement keeps between calls and the small-matrix kernels it runs on: a kept
result is found by its arguments' values (never by an array that changed since), the
vectorised Cholesky factor is LAPACK's, the stacked product is matmul's, and ℓ alone at a
trial point is ℓ with its gradient."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.method.likelihood import road_input
from rozyn_estimator.method.likelihood.kept import Kept
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.stacks import inverse_cholesky, mul
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective
from rozyn_estimator.vehicle import Vehicle


def test_a_kept_result_is_found_by_the_arguments_values_and_the_oldest_goes():
    kept, built = Kept(2), []

    def build(tag: str):
        return lambda: built.append(tag) or tag

    a = np.arange(5.0)
    assert kept.get((a, 1.0), build("a")) == "a"
    assert kept.get((a.copy(), 1.0), build("again")) == "a"  # an equal array, not the same object
    assert kept.get((a, 2.0), build("a2")) == "a2"  # another number
    a[0] = 9.0  # the caller's array changed since: not the one kept
    assert kept.get((a, 1.0), build("changed")) == "changed"
    assert kept.get((np.arange(5.0), 1.0), build("evicted")) == "evicted"  # a, 1.0 went for a, 2.0's
    assert kept.get((np.arange(4.0), None), build("short")) == "short"  # another shape
    assert built == ["a", "a2", "changed", "evicted", "short"]


def test_a_windows_drive_profile_is_computed_once_and_read_only():
    v = np.r_[np.zeros(300), np.linspace(0.0, 12.0, 700), np.full(1000, 12.0)]
    first = road_input.steady_driving(2.5, v, 100.0)
    again = road_input.steady_driving(2.5, v.copy(), 100.0)
    assert again is first and not first.flags.writeable
    other = v.copy()
    other[-500:] = 0.0  # a stop: another profile
    assert not np.array_equal(road_input.steady_driving(2.5, other, 100.0), first)



@pytest.mark.parametrize(("left", "right"), [
    ((7, 2, 2), (7, 2, 2)), ((7, 3, 3), (7, 3, 3)), ((3, 7, 2, 2), (1, 7, 2, 2)),  # element by element
    ((2, 2), (7, 2, 2)), ((1, 7, 2, 2), (3, 1, 2, 2)), ((7, 2, 1), (7, 1, 2)), ((7, 3, 2), (7, 2, 3)),
    ((7, 22, 2), (7, 2, 2)), ((7, 2, 2), (7, 2, 22)), ((7, 4, 4), (7, 4, 4)), ((7, 4, 8), (7, 8, 4)),
])
def test_the_stacked_product_is_matmuls_broadcast_as_it_is(left, right):
    rng = np.random.default_rng(len(left) + left[-1] * right[-1])
    a = rng.standard_normal(left) + 1j * rng.standard_normal(left)
    b = rng.standard_normal(right)  # real times complex, as the sensing's real parts meet S
    for x, y in ((a, b), (b.T.conj() if b.ndim == 2 else np.swapaxes(b, -1, -2), np.swapaxes(a, -1, -2))):
        product = mul(x, y)
        assert product.shape == np.matmul(x, y).shape and product.dtype == np.result_type(x, y)
        np.testing.assert_allclose(product, x @ y, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("k", [2, 3, 4, 5])
def test_the_inverse_cholesky_factor_is_lapacks(k):
    rng = np.random.default_rng(k)
    a = rng.standard_normal((300, k, k)) + 1j * rng.standard_normal((300, k, k))
    S = a @ a.conj().swapaxes(1, 2) + 1e-3 * np.eye(k)
    linv = inverse_cholesky(S)
    assert linv is not None
    np.testing.assert_allclose(linv, np.linalg.inv(np.linalg.cholesky(S)), rtol=1e-10, atol=1e-12)
    not_definite = S.copy()
    not_definite[7] = -not_definite[7]
    assert inverse_cholesky(not_definite) is None
    not_finite = S.copy()
    not_finite[3, 0, 0] = np.nan
    assert inverse_cholesky(not_finite) is None


def test_the_likelihood_alone_is_the_likelihood_with_its_gradient():
    """A line search's trial asks for ℓ alone; asked for the gradient there afterwards, the
    objective gives what a fresh evaluation gives."""
    v = Vehicle()
    freq = np.arange(0.5, 15.0, 1 / 60)
    model = VehicleSpectrum(v, (0, 1), freq, 100.0, 100 / 3.6, kernel_m2_hz2=5e-5, grid_hz=0.05)
    theta = model.theta(np.array([v.sprung_mass_kg, v.pitch_inertia_kgm2, v.cog_from_front_axle_m]),
                        1e-6, np.full(2, 1e-6))
    S, _ = model.spectrum(theta, derivatives=False)
    rng = np.random.default_rng(2)
    x = rng.standard_normal((S.shape[0], 2, 6)) + 1j * rng.standard_normal((S.shape[0], 2, 6))
    periodogram = S @ (x @ x.conj().swapaxes(1, 2) / 6)
    trial = theta + 0.01
    lazy, fresh = (WhittleObjective(model, periodogram) for _ in range(2))
    lazy.fun(theta)
    value = lazy.fun(trial)  # ℓ alone
    assert value == fresh.evaluate(trial)[0]
    np.testing.assert_array_equal(lazy.jac(trial), fresh.jac(trial))
    np.testing.assert_array_equal(lazy.hess(trial), fresh.hess(trial))
