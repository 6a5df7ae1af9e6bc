r"""Nothing stands below the floor: a one-sided prior factor on a thing's base height.

A static distractor's priors are broad on purpose (it may be a poster high on a wall or a
patch on the floor), and with every thing of a map a distractor nothing pins the scale of
the world but the camera's height: the whole map (trajectory, things, sizes) can grow
about the camera, every base sinking below the floor, and pay only the odometry
calibration's prior. On a cluttered bag that state (distance scale -44 %, every real object
a distractor 0.4 m under the floor at twice its size) beat the right map by 6 nats. The
floor is the scale it lacked: the map frame's ``z = 0`` is the floor the robot drives on, and
a thing whose base is under it would be hidden there.

The factor is a hinge on ``z_base``: residual ``r = min(z_base, 0) / s`` with ``s`` the
floor stddev (``sampler.clutter.distractor_floor_stddev_m``): zero above the floor, a Gaussian wall
below it, whose width allows the detector's lower-edge bias on a patch lying on the floor.
Its Jacobian is ``1/s`` where it is active and 0 elsewhere, so Gauss-Newton and the Laplace
evidence treat it as any other factor. The prior of a row with a floor factor is the
Gaussian ``N(z; mu, sigma)`` times ``exp(-r^2 / 2)``, renormalised so that the evidence
stays a density:

    Z = Phi(mu / sigma) + (t / sigma) exp(-mu^2 / (2 (sigma^2 + s^2))) Phi(-m / t),
    t^2 = sigma^2 s^2 / (sigma^2 + s^2),   m = mu s^2 / (sigma^2 + s^2),

(the mass above the floor, and the Gaussian product below it), and the row's log
normalizer gains ``-log Z``: about ``+0.64`` nats for a floor class's distractor
(``mu = 0``: half the Gaussian, and a sliver below).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import log_ndtr

NO_FLOOR = math.inf  # a prior row's floor stddev when it has no floor factor


def floor_residual(z_base_m: ArrayLike, inv_stddev: ArrayLike) -> NDArray[np.float64]:
    """Whitened floor residuals ``min(z_base, 0) / s`` (``inv_stddev = 1/s``, 0: no factor)."""
    return np.minimum(z_base_m, 0.0) * np.asarray(inv_stddev, dtype=float)


def floor_jacobian(z_base_m: ArrayLike, inv_stddev: ArrayLike) -> NDArray[np.float64]:
    """d residual / d z_base: ``1/s`` below the floor, 0 above it."""
    return np.where(np.asarray(z_base_m) < 0.0, inv_stddev, 0.0)


def floor_log_mass(mean_m: float, stddev_m: float, floor_stddev_m: float) -> float:
    """``log Z`` of ``N(z; mean, stddev) exp(-min(z, 0)^2 / (2 floor^2))`` (module docstring); 0 without a floor."""
    if not math.isfinite(floor_stddev_m):
        return 0.0
    sum_var = stddev_m**2 + floor_stddev_m**2
    t = stddev_m * floor_stddev_m / math.sqrt(sum_var)
    m = mean_m * floor_stddev_m**2 / sum_var
    above = float(log_ndtr(mean_m / stddev_m))
    below = math.log(t / stddev_m) - mean_m**2 / (2.0 * sum_var) + float(log_ndtr(-m / t))
    return float(np.logaddexp(above, below))
