r"""The false-alarm (clutter) model: the likelihood of a tracklet that is no object.

Beyond the paper, an association may put a tracklet in the clutter set: its slices are
then explained as false alarms of the detector instead of as views of an object. For the
comparison with an object to be meaningful, both must be densities over the same
measurements in the same units. The object side is the factor graph's Laplace evidence,
which includes every Gaussian normalizer (:mod:`objslam_mapper.solver`): a density over
each slice's 4-vector ``(bearing, angular width, elevation bottom, elevation top)`` in
rad^-4. The clutter side is then a density over the same 4-vector:

False alarms of a class are a Poisson process with ``false_alarm_rate`` expected slices
per image, each uniform over the measurement space

    bearing in [-pi, pi),  width in (0, w_max],  e_min <= bottom <= top <= e_max,

whose volume is ``V = 2 pi * w_max * (e_max - e_min)^2 / 2`` rad^4. Up to factors that do
not depend on the association (``exp(-rate)`` per image and class), a clutter slice
contributes ``rate / V`` and a tracklet of ``n`` slices

    log L_clutter = n * (log rate - log V).

An object's slices contribute their Gaussian densities with detection probability one
(missed detections are not modelled, on either side). So a slice favours the clutter
explanation only where the object explanation of it is poor: with the default noise a
well-fitting slice is worth about ``+15`` nats to an object against ``-5.4`` to clutter,
and a new object pays an Occam price of roughly 10-15 nats (its prior normalizer and
``-1/2 log|information|``). A consistent but misfitting tracklet -- a poster on a wall
seen as a floor object that would need to float, or be flat -- ends in clutter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from objslam_mapper.config import setting


@dataclass(frozen=True)
class ClutterConfig:
    """False-alarm model of the detector (see the module docstring)."""

    enabled: bool = setting(True, "let the sampler explain tracklets as false alarms instead of objects")
    false_alarm_rate: float = setting(
        0.1, "expected false-alarm slices per image and class (Poisson rate)", minimum=1e-12
    )
    max_angular_width_rad: float = setting(1.0, "false-alarm widths are uniform in (0, this] (rad)", minimum=1e-6)
    min_elevation_rad: float = setting(
        -math.pi / 2, "false-alarm edge elevations are uniform above this (rad)", minimum=-math.pi / 2
    )
    max_elevation_rad: float = setting(
        1.12, "... and below this (rad; the bundled camera sees up to asin(0.9) = 1.12)", maximum=math.pi / 2
    )

    def __post_init__(self) -> None:
        if self.max_elevation_rad <= self.min_elevation_rad:
            raise ValueError("max_elevation_rad must be above min_elevation_rad")

    @property
    def measurement_volume(self) -> float:
        """V: volume of the slice measurement space, rad^4."""
        span = self.max_elevation_rad - self.min_elevation_rad
        return 2.0 * math.pi * self.max_angular_width_rad * 0.5 * span * span

    @property
    def log_likelihood_per_slice(self) -> float:
        """log(rate / V): one false-alarm slice's log density (units: log rad^-4)."""
        return math.log(self.false_alarm_rate) - math.log(self.measurement_volume)

    def log_likelihood(self, slice_count: int) -> float:
        """log L of a tracklet of ``slice_count`` slices explained as clutter."""
        return slice_count * self.log_likelihood_per_slice
