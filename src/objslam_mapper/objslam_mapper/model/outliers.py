r"""Slices that are no measurement of their object: a max-mixture slice likelihood.

A blob is not always one object: two same-colour objects lined up merge into one blob, a
poster behind an object lends it its upper edge, an occluder cuts it. Such slices chain
into the same tracklets as the good ones (they change smoothly from image to image), so
the association cannot set them apart, and under a Gaussian likelihood a handful of them
costs hundreds of nats: enough for the sampler to prefer a duplicate object that absorbs
them over the one real object. The slice likelihood is therefore a mixture

    p(z | x) = (1 - eps) N(z; h(x), Sigma) + eps / V,

``eps`` the outlier probability and ``V`` the volume of the measurement space
(``slice_noise.outlier_probability``, ``slice_noise.outlier_volume_rad4``). The solver
uses its max-mixture form (Olson and Agarwal, 2012): each slice takes the larger of the
two components, so with ``q = 1/2 |whitened residual|^2`` the slice's negative log
likelihood is

    -log(1 - eps) - log N_0 + min(q, tau),    tau = log N_0 + log(1 - eps) - log(eps / V),

``log N_0 = -1/2 log|2 pi Sigma|`` the Gaussian normalizer. The constant part is
folded into the problem's measurement normalizers; the solver's cost is the truncated
quadratic ``min(q, tau)``: continuous, Gaussian near the prediction, flat beyond
``tau``, where a slice contributes no information (zero Jacobian). The Laplace evidence
at the MAP is then that of the inlier slices plus ``eps / V`` per outlier, the
max-mixture being within a factor 2 of the mixture for every slice.

With the default noise and ``eps = 0.01`` a floor object's slice turns outlier beyond a
chi-square of about 46 (6.7 sigma in all four components together). A merged tail costs
its object at most ``tau`` per slice; a whole tracklet of another object still costs
``tau`` per slice, far above a new object's Occam factor, so real neighbours stay apart.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray


def outlier_cost(
    gaussian_log_normalizer: NDArray[np.float64], probability: float, volume: float
) -> NDArray[np.float64]:
    """``tau`` per slice (module docstring); inf when ``probability`` is 0 (every slice Gaussian)."""
    normalizer = np.asarray(gaussian_log_normalizer, dtype=float)
    if probability <= 0.0:
        return np.full(normalizer.shape, np.inf)
    return normalizer + math.log1p(-probability) - math.log(probability / volume)


def inlier_log_weight(probability: float) -> float:
    """``log(1 - eps)``: the Gaussian component's weight, part of every slice's normalizer."""
    return math.log1p(-probability) if probability > 0.0 else 0.0


# The solvers minimize in phases, graduating the caps (graduated non-convexity, as in
# Yang et al. 2020): each cap multiplied by the phase's scale, the last phase with the
# true caps (objslam_mapper.graph.linearize.cap_schedule). From drifted odometry, or when
# a move closes a loop, good slices sit far beyond their cap and the truncated cost would
# leave them out instead of moving the poses to fit them, so a cold solve starts Gaussian
# (no cap at all); a warm start is near a solution already, and caps 100 times higher
# (about 68 sigma) still let every slice of a loop closure pull while the slices of
# another object's blob (thousands of sigma off) stay out of the way. The middle phase
# keeps a handful of gross outliers, which pull the first phase's fit aside, from turning
# good slices into outliers when the true caps come: jumping from no cap to the true one
# can leave the solve in that compromise.
COLD_START_CAP_SCALES = (math.inf, 10.0, 1.0)
WARM_START_CAP_SCALES = (100.0, 10.0, 1.0)
# A warm start where more than this share of some object's slices is beyond even the
# raised caps is no warm start for that object (a merge that closes a loop: half of it
# was seen before the drift): the solve then starts Gaussian.
WARM_START_MAX_BEYOND = 0.2


def half_chi2(whitened: NDArray[np.float64]) -> NDArray[np.float64]:
    """``1/2 |r|^2`` per slice of component-major (4, A) whitened residuals."""
    return 0.5 * np.einsum("km,km->m", whitened, whitened)


def truncate(
    whitened: NDArray[np.float64], cost: NDArray[np.float64], half: NDArray[np.float64] | None = None
) -> NDArray[np.bool_]:
    """Cap each slice's ``1/2 |residual|^2`` at ``cost`` in place; True for the slices within it.

    ``whitened`` is component-major (4, A), ``half`` its :func:`half_chi2` if known. A
    capped residual is scaled to norm ``sqrt(2 cost)``, so every solver that sums
    ``1/2 |r|^2`` sees the truncated cost; its Jacobian must be zeroed by the caller (the
    mask says which).
    """
    half = half_chi2(whitened) if half is None else half
    inlier = half <= cost
    if not inlier.all():
        out = ~inlier
        whitened[:, out] *= np.sqrt(cost[out] / half[out])
    return inlier
