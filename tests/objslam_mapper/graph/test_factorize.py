"""The dense path's staircase solve against LAPACK's plain banded solve."""

from __future__ import annotations

from unittest import mock

import numpy as np
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import lapack

from objslam_mapper.graph import factorize
from objslam_mapper.graph.factorize import _whiten


def _banded_cholesky(rng: np.random.Generator, rows: int, half_width: int) -> np.ndarray:
    """Upper banded Cholesky factor (LAPACK storage) of a random positive definite band."""
    band = rng.normal(size=(half_width + 1, rows))
    band[half_width] = np.abs(band[half_width]) + 2.0 * (half_width + 1)  # diagonally dominant
    return scipy.linalg.cholesky_banded(band, lower=False)


def _check_against_plain(seed: int, rows: int, half_width: int, columns: int) -> None:
    rng = np.random.default_rng(seed)
    chol = _banded_cholesky(rng, rows, half_width)
    start_rows = rng.integers(0, rows, size=columns)
    rhs = rng.normal(size=(rows, columns))
    rhs[np.arange(rows)[:, None] < start_rows[None, :]] = 0.0
    expected, info = lapack.dtbtrs(chol, rhs, uplo="U", trans="T")
    assert info == 0

    whitened, gram = _whiten(chol, np.asfortranarray(rhs), start_rows)

    np.testing.assert_allclose(whitened, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gram, expected.T @ expected, rtol=1e-12, atol=1e-12)
    assert np.array_equal(gram, gram.T)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    rows=st.integers(1, 60),
    half_width=st.integers(0, 7),
    columns=st.integers(1, 30),
)
def test_the_staircase_solve_equals_the_plain_solve_and_gram(seed, rows, half_width, columns):
    with mock.patch.object(factorize, "_STAIRCASE_MIN_COLUMNS", 1):  # groups of one column and up
        _check_against_plain(seed, rows, half_width, columns)


def test_the_staircase_at_its_own_threshold():
    for columns in (factorize._STAIRCASE_MIN_COLUMNS - 1, 2 * factorize._STAIRCASE_MIN_COLUMNS, 500):
        _check_against_plain(columns, 300, 41, columns)
