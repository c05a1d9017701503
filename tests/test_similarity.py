"""Similarity transformations to a nonnegative R (ivobs.design.similarity): [Tang2019, eq. (48)]
against its Example 2, the nonnegative inverse eigenvalue constructions, and their limits
(the planar example of [Efimov2013])."""

import numpy as np
import pytest

import ivobs
from ivobs import DesignError, scenarios
from ivobs.design.similarity import (
    circulant_block,
    nonnegative_realization,
    place_real_poles,
    similarity_transform,
    suleimanova_block,
)
from ivobs.linalg import observability_rank


def tang2():
    sc = scenarios.get("tang-example2")
    A, _, C, *_ = sc.system.matrices_at(0)
    return sc, A, C


def S_from_printed(p, A, C, e1, e2):
    """S by eq. (48) from the printed (L1, L2, R11, R12, R22)."""
    L = np.array([[p[0]], [p[1]]])
    R = np.array([[p[2], p[3]], [0.0, p[4]]])
    return similarity_transform(A - L @ C, R, e1, e2)


def test_eq48_reproduces_tang_example2():
    """[Tang2019, Example 2] prints L, R, e1, e2 and S to four decimals. S is sensitive to the
    rounding of its inputs (|∂S/∂R11| up to 15, |∂S/∂R22| up to 15: R22 = 0.0003 is printed with
    one significant digit), so the tolerance is the first-order effect of rounding every input
    by half a unit of the last printed digit, plus the rounding of S itself."""
    sc, A, C = tang2()
    ref = sc.reference
    p0 = np.array([ref["L"][0, 0], ref["L"][1, 0], ref["R"][0, 0], ref["R"][0, 1], ref["R"][1, 1]])
    S = S_from_printed(p0, A, C, ref["e1"], ref["e2"])
    h = 1e-7
    jac = [
        (
            S_from_printed(p0 + h * e, A, C, ref["e1"], ref["e2"])
            - S_from_printed(p0 - h * e, A, C, ref["e1"], ref["e2"])
        )
        / (2 * h)
        for e in np.eye(5)
    ]
    tol = 0.5e-4 * np.abs(np.array(jac)).sum(axis=0) + 0.5e-4
    assert np.all(tol < 2.2e-3)
    assert np.all(np.abs(S - ref["S"]) <= tol), (S, ref["S"], tol)
    # same numbers through the estimator, which propagates with S (A − LC) S⁻¹ ≈ R
    est = ivobs.make_estimator(
        "interval-transformed",
        sc.system,
        x0=sc.x0,
        L=ref["L"],
        R=ref["R"],
        e1=ref["e1"],
        e2=ref["e2"],
    )
    np.testing.assert_allclose(est.design.S, S, rtol=1e-12)
    np.testing.assert_allclose(est.design.R, ref["R"], atol=5e-4)
    assert est.design.R.min() >= 0


def test_eq48_is_a_similarity_for_consistent_inputs():
    rng = np.random.default_rng(0)
    for n in (2, 3, 4):
        A = rng.normal(size=(n, n))
        C = rng.normal(size=(1, n))
        poles = np.linspace(0.1, 0.7, n)
        L = place_real_poles(A, C, poles, "test")
        M = A - L @ C
        R, e2 = nonnegative_realization(np.linalg.eigvals(M))
        S = similarity_transform(M, R, rng.normal(size=n), e2)
        np.testing.assert_allclose(S @ M @ np.linalg.inv(S), R, atol=1e-8)


def test_unobservable_pairs_are_named():
    sc, A, C = tang2()
    M = A - sc.reference["L"] @ C
    with pytest.raises(DesignError, match=r"\(R, e2\) is not observable.*choose another e2"):
        similarity_transform(M, np.diag([0.3, 0.1]), np.array([1.0, 0.0]), np.array([1.0, 0.0]))
    with pytest.raises(DesignError, match=r"\(A − LC, e1\) is not observable"):
        similarity_transform(
            np.diag([0.3, 0.1]), np.diag([0.3, 0.1]), np.array([0.0, 1.0]), np.ones(2)
        )


def test_planar_example_spectrum_has_no_nonnegative_realisation():
    """[Efimov2013, Section IV.A] with L = (0.3, 0.6): λ(A − LC) = {0, −0.5}. The paper prints
    R = [[−0.5, 0], [1, 0]], which is not nonnegative; no nonnegative R exists (trace < 0)."""
    sc = scenarios.get("efimov-planar")
    A, _, C, *_ = sc.system.matrices_at(0)
    lam = np.linalg.eigvals(A - sc.reference["L"] @ C)
    np.testing.assert_allclose(np.sort(lam.real), [-0.5, 0.0], atol=1e-12)
    with pytest.raises(DesignError, match=r"\{0, -0.5\} exists: its trace is -0.5 < 0"):
        nonnegative_realization(lam)
    with pytest.raises(DesignError, match=r"trace is -0.5 < 0"):
        ivobs.make_estimator("interval-transformed", sc.system, x0=sc.x0, L=sc.reference["L"])
    with pytest.raises(DesignError, match=r"R is not nonnegative: entry \(1, 1\) = -0.5"):
        ivobs.make_estimator(
            "interval-transformed", sc.system, x0=sc.x0, L=sc.reference["L"], R=sc.reference["R"]
        )


@pytest.mark.parametrize(
    "eigs, kind",
    [
        ([0.5, 0.2, 0.1], "diagonal"),
        ([0.5, 0.5, 0.1], "jordan"),
        ([0.9, -0.3, -0.4], "suleimanova"),
        ([0.9, 0.5, -0.4, -0.3, -0.2], "two groups"),
        ([0.8, 0.3 + 0.2j, 0.3 - 0.2j], "circulant"),
        ([0.9, 0.1, 0.2 + 0.3j, 0.2 - 0.3j, -0.1], "mixed"),
        ([0.0, 0.0], "nilpotent"),
    ],
)
def test_realisations_are_nonnegative_with_the_spectrum(eigs, kind):
    R, e2 = nonnegative_realization(np.array(eigs))
    assert R.min() >= 0
    got = np.linalg.eigvals(R)
    tol = 1e-6 if kind in ("jordan", "nilpotent") else 1e-9  # defective: sqrt(eps) splitting
    for z in eigs:
        assert np.min(np.abs(got - z)) < tol, (kind, got)
    assert observability_rank(R, e2[None, :]) == len(eigs)
    if kind == "diagonal":
        np.testing.assert_array_equal(R, np.diag([0.5, 0.2, 0.1]))


@pytest.mark.parametrize(
    "eigs, reason",
    [
        ([0.5, 0.5, -0.6], r"spectral radius 0.6 is not an eigenvalue"),
        ([0.5, 0.2, -0.6], r"power sum s_3 = trace\(R\^3\) is -0.083 < 0"),
        ([0.9, -0.6 + 0.1j, -0.6 - 0.1j], r"trace is -0.3 < 0"),
        ([0.3, 0.25 + 0.1j, 0.25 - 0.1j], r"complex pair 0.25 ± 0.1j needs a real eigenvalue"),
        ([0.5, 0.4, -0.45, -0.44], r"negative eigenvalue -0.44 \(x1\) does not fit"),
        ([0.6, 0.6, 0.1 + 0.2j, 0.1 - 0.2j, 0.1 + 0.2j, 0.1 - 0.2j], r"repeated complex pairs"),
    ],
)
def test_unsupported_spectra_say_why(eigs, reason):
    with pytest.raises(DesignError, match=reason):
        nonnegative_realization(np.array(eigs))


def test_suleimanova_and_circulant_blocks():
    rng = np.random.default_rng(1)
    for _ in range(30):
        mu = rng.uniform(0, 1, rng.integers(1, 5))
        rho = mu.sum() * rng.uniform(1.0, 2.0)
        R = suleimanova_block(rho, list(-mu))
        assert R.min() >= -1e-12
        np.testing.assert_allclose(
            np.sort(np.linalg.eigvals(R).real), np.sort(np.concatenate([[rho], -mu])), atol=1e-8
        )
    # triangle condition: a ± ib inside the triangle with vertices ρ, ρω, ρω²
    R = circulant_block(1.0, complex(0.2, 0.4))
    assert R.min() >= 0
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(R)),
        np.sort_complex([1.0, 0.2 + 0.4j, 0.2 - 0.4j]),
        atol=1e-12,
    )
    assert circulant_block(1.0, complex(0.2, 0.5)).min() < 0  # 0.2 + √3·0.5 > 1


def _notation_cell(row_start: str, paper: str) -> str:
    """The cell of docs/notation.md's table in the row starting with ``row_start`` and the
    column of ``paper``."""
    from pathlib import Path

    lines = (Path(__file__).parents[1] / "docs" / "notation.md").read_text().splitlines()
    header = next(ln for ln in lines if ln.startswith("| ivobs |"))
    col = next(i for i, c in enumerate(header.split("|")) if paper in c)
    rows = [ln for ln in lines if ln.startswith("| " + row_start)]
    assert len(rows) == 1, f"docs/notation.md: no single row starting with {row_start!r}"
    return rows[0].split("|")[col].strip()


def test_efimov_transformation_is_the_inverse_of_ivobs_as_the_notation_table_says():
    """[Efimov2013, Theorem 2] uses z = S⁻¹ x (observer (4): x̲ = S⁺ z̲ − S⁻ z̄, F = S⁻¹ L), so its
    S is ivobs' S⁻¹. The table states the orientation; ivobs' design on the planar example
    satisfies the paper's relation in it, the paper's printed S does too, and observer (4)
    written as in the paper with that S gives ivobs' boxes."""
    cell = _notation_cell("`interval-transformed`: `S`, `z = S x`", "[Efimov2013]")
    inverse = cell.startswith("`S⁻¹`")
    relations = {
        "R = S⁻¹ (A − LC) S": lambda S, M: np.linalg.solve(S, M @ S),
        "R = S (A − LC) S⁻¹": lambda S, M: S @ M @ np.linalg.inv(S),
    }
    stated = [rel for rel in relations if rel in cell]
    assert len(stated) == 1, cell
    relation = relations[stated[0]]

    sc = scenarios.get("efimov-planar", horizon=60)
    A, B, C, *_ = sc.system.matrices_at(0)
    # the paper's observer: without the finite-memory bound
    est = ivobs.make_estimator("interval-transformed", sc.system, x0=sc.x0, finite_memory=False)
    d = est.design
    S_paper = np.linalg.inv(d.S) if inverse else d.S
    M = A - d.L @ C
    np.testing.assert_allclose(relation(S_paper, M), d.R, atol=1e-12)
    assert d.R.min() >= -1e-15
    # the paper's printed S (§IV.A, L = (0.3, 0.6)) in the stated orientation: triangular with
    # λ(A − LC) = {0, −0.5} on the diagonal, to its printed digits
    Mp = A - sc.reference["L"] @ C
    Rp = relation(sc.reference["S"], Mp)
    np.testing.assert_allclose(Rp, [[0.0, 0.0], [1.0, -0.5]], atol=1.5e-3)

    # observer (4) as the paper writes it, with S = S_paper
    traj = sc.simulate("paper")
    res = est.run(traj.u, traj.y)
    Si = np.linalg.inv(S_paper)
    F = Si @ d.L
    Fbar = np.abs(F) @ np.ones(1)
    delta, V = 0.5, 0.1
    pos, neg = np.maximum(Si, 0), np.maximum(-Si, 0)
    zlo = pos @ sc.x0.lo - neg @ sc.x0.hi
    zhi = pos @ sc.x0.hi - neg @ sc.x0.lo
    for k in range(traj.y.shape[0] - 1):
        b0 = B @ traj.u[k]
        zlo, zhi = (
            d.R @ zlo + F @ traj.y[k] - Fbar * V + pos @ (b0 - delta) - neg @ (b0 + delta),
            d.R @ zhi + F @ traj.y[k] + Fbar * V + pos @ (b0 + delta) - neg @ (b0 - delta),
        )
        Sp, Sn = np.maximum(S_paper, 0), np.maximum(-S_paper, 0)
        xlo, xhi = Sp @ zlo - Sn @ zhi, Sp @ zhi - Sn @ zlo
        np.testing.assert_allclose(res.lower[k + 1], xlo, rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.upper[k + 1], xhi, rtol=0, atol=1e-9)
        assert np.all(xlo <= traj.x[k + 1]) and np.all(traj.x[k + 1] <= xhi)
