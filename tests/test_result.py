"""Estimate: containment semantics, metrics, CSV round trip."""

import numpy as np
import pytest

from ivobs import Estimate, IvobsError


def _est():
    lo = np.array([[np.nan, np.nan], [0.0, -1.0], [0.5, -0.5]])
    hi = np.array([[np.nan, np.nan], [1.0, 1.0], [1.5, 0.5]])
    return Estimate(lo, hi, valid_from=1, method="demo")


def test_contains_and_metrics():
    e = _est()
    x = np.array([[9.0, 9.0], [0.5, 0.0], [2.0, 0.0]])
    np.testing.assert_array_equal(e.contains(x), [True, True, False])
    assert e.contains(x, tol=0.6).all()
    np.testing.assert_allclose(e.mean_width(), [1.0, 1.5])
    np.testing.assert_allclose(e.mean_width(burn_in=2), [1.0, 1.0])
    ref = Estimate(
        e.lower * 0 + np.array([0.25, -0.25]), e.upper * 0 + np.array([0.75, 0.25]), valid_from=1
    )
    np.testing.assert_allclose(e.tightness_ratio(ref), [2.0, 3.0])
    assert e.box(0).is_unknown and e.box(1).hi[0] == 1.0
    assert e.T == 3 and e.nx == 2 and e.valid.tolist() == [False, True, True]
    with pytest.raises(IvobsError, match="no valid step"):
        e.mean_width(burn_in=5)
    with pytest.raises(IvobsError, match="expected x of shape"):
        e.contains(np.zeros((2, 2)))


def test_nan_after_valid_from_does_not_contain():
    e = _est()
    e.lower[2, 0] = np.nan
    assert not e.contains(np.array([[0, 0], [0.5, 0], [1.0, 0.0]]))[2]


def test_csv_round_trip(tmp_path):
    e = _est()
    e.lower[2, 1] = -0.1234567890123456789
    e.missing = np.array([False, True, False])
    p = tmp_path / "est.csv"
    e.to_csv(p)
    back = Estimate.from_csv(p)
    assert back.equals(e) and back.missing.tolist() == [False, True, False]
    assert not any(f.suffix == ".tmp" for f in tmp_path.iterdir())
    (tmp_path / "bad.csv").write_text("# ivobs estimate\nk,lower_1,upper_1\n0,1,x\n")
    with pytest.raises(IvobsError, match="malformed row"):
        Estimate.from_csv(tmp_path / "bad.csv")
    with pytest.raises(IvobsError, match="no such file"):
        Estimate.from_csv(tmp_path / "missing.csv")


def test_shape_validation():
    with pytest.raises(IvobsError, match="share a"):
        Estimate(np.zeros((3, 2)), np.zeros((3, 3)))
