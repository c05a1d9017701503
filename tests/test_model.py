"""LinearSystem: one model, validated; conversions and structural facts."""

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem, linalg

A = np.array([[0.5, 0.1], [0.0, 0.3]])
C = np.array([[1.0, 0.0]])


def test_minimal_system_and_dimensions():
    s = LinearSystem(A, C=C)
    assert (s.nx, s.nu, s.ny, s.nd) == (2, 0, 1, 0)
    assert s.is_discrete and not s.is_time_varying and s.sampling_period == 1.0
    assert s.B.shape == (2, 0) and s.D.shape == (1, 0)
    assert s.d_at(0).dim == 0


def test_full_system_accepts_vectors_for_single_columns():
    s = LinearSystem(
        A, [0.0, 1.0], [1.0, 0.0], D=[0.5], E=[1.0, 1.0], F=[0.1], d=Box([-1.0], [2.0]), dt=0.1
    )
    assert s.B.shape == (2, 1) and s.C.shape == (1, 2) and s.E.shape == (2, 1)
    assert s.F.shape == (1, 1) and s.dt == 0.1


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(E=np.ones((2, 1))), "E: a disturbance matrix was given without bounds d"),
        (dict(F=np.ones((1, 1))), "F: a disturbance matrix was given without bounds d"),
        (dict(d=Box([-1], [1])), "neither E nor F"),
        (dict(E=np.ones((2, 2)), d=Box([-1], [1])), "E: expected shape (2, 1), got (2, 2)"),
        (dict(B=np.ones((3, 1))), "B: expected shape (2, any), got (3, 1)"),
        (dict(D=np.ones((1, 2)), B=np.ones((2, 1))), "D: expected shape (1, 1), got (1, 2)"),
        (dict(E=np.ones((2, 1)), d=[-1, 1]), "expected an ivobs.Box or a callable"),
        (dict(dt=-1), "dt: expected True, a period > 0, or 0"),
        (dict(dt=None), "dt: expected True or a period"),
        (dict(E=np.ones((2, 1)), d=Box([-np.inf], [1])), "finite"),
    ],
)
def test_rejects_bad_models(kwargs, message):
    with pytest.raises(IvobsError, match=message.replace("(", r"\(").replace(")", r"\)")):
        LinearSystem(A, C=C, **kwargs)


def test_rejects_non_finite_and_non_square():
    with pytest.raises(IvobsError, match="A: expected finite numbers, found non-finite"):
        LinearSystem(np.array([[np.nan, 0], [0, 1]]), C=C)
    with pytest.raises(IvobsError, match="A: expected a square matrix"):
        LinearSystem(np.ones((2, 3)), C=np.ones((1, 2)))
    with pytest.raises(IvobsError, match="C: the output matrix is required"):
        LinearSystem(A)
    with pytest.raises(IvobsError, match=r"C: expected shape \(any, 2\), got \(1, 3\)"):
        LinearSystem(A, C=np.ones((1, 3)))


def test_time_varying_matrices_callable_and_stacked():
    s = LinearSystem(lambda k: A * (1 + 0.1 * np.sin(k)), C=C)
    assert s.is_time_varying
    np.testing.assert_allclose(s.A_at(3), A * (1 + 0.1 * np.sin(3)))
    stack = np.stack([A, 2 * A, 3 * A])
    s2 = LinearSystem(stack, C=C)
    np.testing.assert_array_equal(s2.A_at(2), 3 * A)
    with pytest.raises(IvobsError, match="step 3 is beyond the 3 stacked"):
        s2.A_at(3)
    with pytest.raises(IvobsError, match=r"A\(0\): expected finite"):
        LinearSystem(lambda k: np.full((2, 2), np.inf), C=C)
    bad = LinearSystem(lambda k: A if k == 0 else np.ones((3, 3)), C=C)
    with pytest.raises(IvobsError, match=r"A\(1\): expected shape \(2, 2\)"):
        bad.A_at(1)
    with pytest.raises(IvobsError, match="defined for time-invariant systems"):
        s.is_observable()


def test_bounds_time_varying_and_callable():
    lo = -np.ones((4, 1)) * np.arange(1, 5)[:, None]
    s = LinearSystem(A, C=C, E=np.ones((2, 1)), d=Box(lo, -lo))
    assert s.d_at(3) == Box([-4.0], [4.0])
    assert not s.has_constant_bounds
    s2 = LinearSystem(A, C=C, F=np.ones((1, 1)), d=lambda k, y: Box([-abs(y[0])], [abs(y[0])]))
    assert s2.nd == 1 and s2.d_at(0, np.array([2.0])) == Box([-2.0], [2.0])
    s3 = LinearSystem(A, C=C, F=np.ones((1, 1)), d=lambda k, y: Box([0, 0], [1, 1]))
    with pytest.raises(IvobsError, match="must return an ivobs.Box of dimension 1"):
        s3.d_at(0, np.zeros(1))


def test_process_measurement_constructor_stacks_w_and_v_into_one_disturbance():
    Ew = np.eye(2)
    Fv = np.array([[2.0]])
    s = LinearSystem.from_process_measurement(A, np.zeros((2, 1)), C, Ew, Fv, [0.1, 0.2], [0.3])
    np.testing.assert_array_equal(s.E, [[1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(s.F, [[0, 0, 2]])
    assert s.d == Box([-0.1, -0.2, -0.3], [0.1, 0.2, 0.3])


def test_observability_and_schur_helpers():
    s = LinearSystem(A, C=C)
    assert s.is_observable() and s.observability_rank() == 2 and s.is_stable()
    unobs = LinearSystem(np.diag([0.5, 0.3]), C=C)
    assert unobs.observability_rank() == 1 and not unobs.is_observable()
    assert linalg.is_schur(A) and not linalg.is_schur(2 * np.eye(2))
    assert linalg.spectral_radius(np.array([[0, 1], [-1, 0]])) == pytest.approx(1.0)
    assert linalg.is_hurwitz(-np.eye(2)) and linalg.is_metzler(np.array([[-1, 1], [0, -1]]))
    with pytest.raises(IvobsError, match="not observable: rank 1 of 2"):
        linalg.check_observable(np.diag([0.5, 0.3]), C, "this test")


def test_observability_indices():
    # chain of 3 integrators measured at the end: one output, index 3
    A_chain3 = np.diag([1.0, 1.0], 1)
    assert linalg.observability_indices(A_chain3, [[0, 0, 1.0]]) == [1]
    assert linalg.observability_indices(A_chain3, [[1.0, 0, 0]]) == [3]
    # two outputs on a 4-state system: indices sum to the rank
    A_chain4 = np.diag([1.0, 0, 1.0], 1)
    C_chain4 = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    m = linalg.observability_indices(A_chain4, C_chain4)
    assert m == [2, 2] and sum(m) == linalg.observability_rank(A_chain4, C_chain4)
    assert linalg.is_controllable(A_chain3, [[0], [0], [1.0]])


def test_statespace_round_trip():
    control = pytest.importorskip("control")
    s = LinearSystem(A, [[0.0], [1.0]], C, dt=0.1)
    ss = control.ss(s.A, s.B, s.C, s.D, 0.1)
    s2 = LinearSystem.from_statespace(ss, E=np.eye(2), d=Box([-1, -1], [1, 1]))
    np.testing.assert_array_equal(s2.A, A)
    assert s2.dt == 0.1 and s2.nd == 2
    back = s2.to_statespace()
    assert back.ninputs == 3 and back.dt == 0.1
    with pytest.raises(IvobsError, match="expected a control.StateSpace"):
        LinearSystem.from_statespace(object())


def test_discretize_is_exact_for_held_signals():
    from scipy.linalg import expm

    Ac = np.array([[0.0, 1.0], [-2.0, -0.5]])
    s = LinearSystem(Ac, [[0.0], [1.0]], [[1.0, 0.0]], E=[[0.0], [1.0]], d=Box([-1], [1]), dt=0)
    assert s.is_continuous
    sd = s.discretize(0.1, disturbances="held")
    np.testing.assert_allclose(sd.A, expm(Ac * 0.1))
    # B_d = ∫_0^Ts e^{As} ds B = A⁻¹(e^{A Ts} − I) B for invertible A
    integral = np.linalg.solve(Ac, expm(Ac * 0.1) - np.eye(2))
    np.testing.assert_allclose(sd.B, integral @ np.array([[0.0], [1.0]]), atol=1e-12)
    assert sd.dt == 0.1 and sd.d == s.d
    with pytest.raises(IvobsError, match="already discrete"):
        sd.discretize(0.1)


def test_repr():
    assert "nx=2" in repr(LinearSystem(A, C=C))
    assert isinstance(ivobs.LinearSystem(A, C=C), LinearSystem)


def test_sparse_matrices_are_kept_sparse_with_dense_views_on_demand():
    import scipy.sparse as sp

    n = 500
    A = sp.diags([np.full(n - 1, 0.2), np.full(n, 0.5), np.full(n - 1, 0.2)], [-1, 0, 1])
    C = sp.csr_matrix((np.ones(2), ([0, 1], [10, 400])), shape=(2, n))
    s = LinearSystem(A, C=C, E=sp.eye(n), d=Box(-0.01 * np.ones(n), 0.01 * np.ones(n)))
    assert s.is_sparse and s.nx == n and s.nd == n and s.ny == 2
    assert sp.issparse(s.sparse("A")) and s.sparse("A").nnz == 3 * n - 2
    np.testing.assert_array_equal(s.A, A.toarray())  # dense view for methods without sparsity
    assert sp.issparse(s.sparse("C"))
    with pytest.raises(IvobsError, match=r"E: expected shape \(500, 400\), got \(400, 400\)"):
        LinearSystem(A, C=C, E=sp.eye(400), d=Box(np.zeros(400), np.zeros(400)))
    bad = sp.csr_matrix(([np.inf], ([0], [0])), shape=(n, n))
    with pytest.raises(IvobsError, match="finite numbers in the sparse matrix"):
        LinearSystem(bad, C=C)


def test_linear_system_answers_every_member_of_the_model_protocols():
    """Estimators use a model through ivobs.model.SystemModel / LinearModel only."""
    from ivobs.model import LinearModel, SystemModel

    sys = LinearSystem(A, C=C, E=np.eye(2), d=Box([-0.1, -0.1], [0.1, 0.1]))
    for proto in (SystemModel, LinearModel):
        members = [n for n in vars(proto) if not n.startswith("_")]
        assert members and all(hasattr(sys, n) for n in members), proto
    assert "matrices_at" in vars(LinearModel) and "d_at" in vars(SystemModel)
