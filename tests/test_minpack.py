"""The reproducible MINPACK Levenberg-Marquardt (panto.identification.estimation.minpack): the
padded problem has the unpadded problem's solution, reached by an independent method too.
That the padding removes the heap-dependent read is shown by valgrind (module notes); no test
here can force the heap state under which SciPy's own call varied, so none pretends to."""
import numpy as np
import pytest
from scipy import optimize

from panto.identification.estimation.minpack import levenberg_marquardt


def _problem():
    """A nonlinear exponential-decay fit with a known optimum near (2.0, 0.7, 0.3)."""
    rng = np.random.default_rng(11)
    t = np.linspace(0.0, 5.0, 400)
    y = 2.0 * np.exp(-0.7 * t) + 0.3 + 0.01 * rng.standard_normal(t.size)

    def fun(x):
        return x[0] * np.exp(-x[1] * t) + x[2] - y

    def jac(x):
        e = np.exp(-x[1] * t)
        return np.column_stack([e, -x[0] * t * e, np.ones_like(t)])

    return fun, jac


@pytest.mark.parametrize("analytic", [True, False])
def test_the_padded_fit_reaches_the_optimum_an_independent_method_finds(analytic):
    fun, jac = _problem()
    start = np.array([1.0, 1.5, 0.0])
    ours = levenberg_marquardt(fun, start, jac=jac if analytic else "2-point", x_scale="jac",
                               xtol=1e-12, ftol=1e-12)
    trust_region = optimize.least_squares(fun, start, jac=jac, method="trf", xtol=1e-12,
                                          ftol=1e-12, gtol=1e-12)
    assert ours.success
    assert ours.x.shape == (3,) and ours.jac.shape == (400, 3) and ours.grad.shape == (3,)
    np.testing.assert_allclose(ours.x, trust_region.x, rtol=1e-6)
    assert ours.cost == pytest.approx(trust_region.cost, rel=1e-9)
    # the returned Jacobian is the real parameters' at the optimum (the padding column dropped)
    np.testing.assert_allclose(ours.jac, jac(ours.x), rtol=1e-6, atol=1e-8)


def test_an_array_scale_is_extended_to_the_padding():
    fun, jac = _problem()
    result = levenberg_marquardt(fun, np.array([1.0, 1.5, 0.0]), jac=jac,
                                 x_scale=np.array([1.0, 0.5, 0.1]))
    np.testing.assert_allclose(result.x, [2.0, 0.7, 0.3], atol=0.02)

