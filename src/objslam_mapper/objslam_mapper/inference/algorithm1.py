r"""Building the object map from association samples (paper Algorithm 1, eqs. 16-24).

Each kept sample J_n comes with its MAP estimate and marginals (one factor-graph solve),
summarized as a :class:`SampleSummary`. An object's identity ``ID`` is the set of global
measurement indices it owns, so the same physical hypothesis is recognized across samples
whatever its object number.

Beyond the paper, identities are recognized up to a minority of their measurements
(``identity_overlap``, 0.8 by default; 1 is the paper's exact identity): two sample objects
are the same identity when each holds at least that share of the other's measurements.
The chain is rightly unsure about a short tracklet beside an object (a blob merged with a
neighbour for a few frames: the object's, clutter, or outliers), and with exact identities
that doubt splits one well-determined object into variants that differ by those few
slices, none of them above 1/2. Exact identities are grouped greedily, the most frequent
first, each joining the first group whose most frequent identity it overlaps so; as the
share is above 1/2, two objects of one sample (disjoint) never join one group. Then

- an object of a sample is *spurious* (paper section 3.2) when its location is poorly
  determined: the largest standard deviation of its horizontal location marginal,
  ``sqrt(lambda_max(C_xy))`` in metres, exceeds ``spurious_location_stddev_m`` (0.30 m by
  default). The paper writes "maximum singular value sigma_max > 30 cm" of the marginal
  covariance; a covariance's singular values are variances (m^2), so a threshold in cm
  must mean the standard deviation along the principal axis. Only x, y are used: z_base
  is pinned by the class prior for floor objects and would never decide;
- a sample *yields* ``ID`` when it holds a non-spurious object owning ``ID`` (up to the
  overlap above); ``P(ID|Z)`` is the fraction of samples yielding it (eq. 24);
- the map holds the identities with ``P(ID|Z) > existence_threshold`` (1/2), the rest seen
  often enough are reported as rejected;
- an identity's location and size are averages over the samples yielding it (eqs. 19-20),
  its covariance the mixture's (mean covariance plus the spread of the means; each
  sample's covariance is that of its estimate's error when the solver reports it, else its
  marginal);
  identities that no sample yields are averaged over the samples holding them;
- the trajectory is the average over all samples (eq. 18), headings averaged on the circle;
- the odometry calibration (when the graph estimates it) is averaged like an object (mean
  over all samples, mixture covariance) and reported in the diagnostics under
  ``odometry_calibration``.

Samples are given with multiplicities: the chain repeats states, and a repeated state
needs its solve once.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from objslam_mapper.config import SamplerConfig
from objslam_mapper.errors import MapperError
from objslam_mapper.map_file import BuiltMap, MappedObject, TrajectoryPose


class MapBuildError(MapperError, ValueError):
    """Samples that do not make a map (none, or of different trajectories)."""


@dataclass(frozen=True, eq=False)
class SampleObject:
    """One object of one sample: its identity and its MAP estimate with marginals."""

    identity: frozenset[int]  # global measurement indices
    label: str
    location_m: NDArray[np.float64]  # (3,) x, y, z_base
    size_m: NDArray[np.float64]  # (2,) diameter, height
    location_cov: NDArray[np.float64]  # (3, 3) m^2, posterior marginal: the spurious test's
    size_cov: NDArray[np.float64]  # (2, 2) m^2
    # (5, 5) m^2, location then size: the covariance of the estimate's error, reported
    # instead of the marginals when known (objslam_mapper.graph.error_covariance).
    error_cov: NDArray[np.float64] | None = None


@dataclass(frozen=True, eq=False)
class SampleSummary:
    """What Algorithm 1 needs of one association sample."""

    map_T_base: NDArray[np.float64]  # (N, 3)
    objects: tuple[SampleObject, ...]
    # Odometry calibration (distance scale, turn scale, turn bias rad/m) and its marginal covariance;
    # empty when the graph does not estimate it.
    calibration: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    calibration_cov: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))


def location_stddev_m(location_cov: NDArray[np.float64]) -> float:
    """Largest standard deviation of the horizontal location: sqrt of the top eigenvalue of C_xy."""
    cov_xy = np.asarray(location_cov, dtype=float)[:2, :2]
    if not np.all(np.isfinite(cov_xy)):
        return math.inf  # no marginal (a failed solve): nothing is known of the location
    return math.sqrt(max(float(np.linalg.eigvalsh(0.5 * (cov_xy + cov_xy.T))[-1]), 0.0))


def is_spurious(obj: SampleObject, threshold_m: float) -> bool:
    return location_stddev_m(obj.location_cov) > threshold_m


@dataclass
class _Identity:
    """Running sums over the samples holding one identity (weighted by multiplicity)."""

    label: str
    weight: dict[bool, float] = field(default_factory=lambda: {True: 0.0, False: 0.0})  # key: yielded
    sums: dict[bool, list[NDArray[np.float64]]] = field(default_factory=dict)

    @property
    def held(self) -> float:
        return self.weight[True] + self.weight[False]

    def _accumulate(self, yielded: bool, terms: list[NDArray[np.float64]], weight: float) -> None:
        if yielded in self.sums:
            for acc, term in zip(self.sums[yielded], terms, strict=True):
                acc += term
        else:
            self.sums[yielded] = [t.copy() for t in terms]
        self.weight[yielded] += weight

    def absorb(self, other: _Identity) -> None:
        for yielded, terms in other.sums.items():
            self._accumulate(yielded, terms, other.weight[yielded])

    def add(self, obj: SampleObject, count: float, yielded: bool) -> None:
        vec = np.concatenate([obj.location_m, obj.size_m])
        if obj.error_cov is not None:
            cov = np.asarray(obj.error_cov, dtype=float)
        else:
            cov = np.zeros((5, 5))
            cov[:3, :3], cov[3:, 3:] = obj.location_cov, obj.size_cov
        self._accumulate(yielded, [count * vec, count * np.outer(vec, vec), count * cov], count)

    def moments(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Mean (5,) and mixture covariance (5, 5) over yielding samples, else over all."""
        key = True if self.weight[True] > 0 else False
        w = self.weight[key]
        mean_vec, second, mean_cov = (s / w for s in self.sums[key])
        spread = second - np.outer(mean_vec, mean_vec)
        return mean_vec, mean_cov + 0.5 * (spread + spread.T)


def _group_identities(
    identities: dict[frozenset[int], _Identity], overlap: float
) -> tuple[list[tuple[frozenset[int], _Identity]], dict[frozenset[int], int]]:
    """Exact identities grouped up to ``overlap`` (module docstring): (most frequent member, merged
    sums) per group, and the group of each exact identity."""
    groups: list[tuple[frozenset[int], _Identity]] = []
    group_of: dict[frozenset[int], int] = {}
    ordered = sorted(identities.items(), key=lambda item: (-item[1].held, min(item[0])))
    for identity, entry in ordered:
        for k, (head, merged) in enumerate(groups):
            if merged.label != entry.label:
                continue
            shared = len(identity & head)
            if shared >= overlap * len(identity) and shared >= overlap * len(head):
                merged.absorb(entry)
                group_of[identity] = k
                break
        else:
            fresh = _Identity(entry.label)
            fresh.absorb(entry)
            group_of[identity] = len(groups)
            groups.append((identity, fresh))
    return groups, group_of


def _mean_trajectory(weighted: Sequence[tuple[NDArray[np.float64], float]]) -> NDArray[np.float64]:
    total = sum(w for _, w in weighted)
    xy = sum(w * p[:, :2] for p, w in weighted) / total
    sin = sum(w * np.sin(p[:, 2]) for p, w in weighted)
    cos = sum(w * np.cos(p[:, 2]) for p, w in weighted)
    return np.column_stack([xy, np.arctan2(sin, cos)])


CALIBRATION_NAMES = ("distance_scale", "turn_scale", "turn_bias_rad_per_m")


def _mean_calibration(weighted: Sequence[tuple[SampleSummary, float]]) -> dict[str, Any] | None:
    """Mixture mean and covariance of the samples' odometry calibrations, as plain numbers."""
    rows = [
        (np.asarray(s.calibration, dtype=float), np.asarray(s.calibration_cov, dtype=float), w) for s, w in weighted
    ]
    if not rows or any(len(c) != len(CALIBRATION_NAMES) for c, _, _ in rows):
        return None
    total = sum(w for _, _, w in rows)
    mean = sum(w * c for c, _, w in rows) / total
    second = sum(w * (cov + np.outer(c, c)) for c, cov, w in rows) / total
    cov = second - np.outer(mean, mean)
    cov = 0.5 * (cov + cov.T)
    out: dict[str, Any] = {name: float(v) for name, v in zip(CALIBRATION_NAMES, np.asarray(mean), strict=True)}
    out.update(
        {
            f"{name}_stddev": float(math.sqrt(max(v, 0.0)))
            for name, v in zip(CALIBRATION_NAMES, np.diag(cov), strict=True)
        }
    )
    out["covariance"] = [[float(v) for v in row] for row in cov]
    return out


class MapOptions(NamedTuple):
    """How Algorithm 1 reads the samples (module docstring); :meth:`of` takes the sampler's settings."""

    spurious_location_stddev_m: float = 0.30
    existence_threshold: float = 0.5
    # Identities that no sample yields are reported as rejected when at least this fraction
    # of the samples hold them (spurious or not).
    report_min_fraction: float = 0.05
    identity_overlap: float = 1.0

    @classmethod
    def of(cls, config: SamplerConfig) -> MapOptions:
        return cls(
            spurious_location_stddev_m=config.spurious_location_stddev_m,
            existence_threshold=config.existence_threshold,
            report_min_fraction=config.report_min_fraction,
            identity_overlap=config.identity_overlap,
        )


def build_from_samples(
    samples: Iterable[tuple[SampleSummary, float]],
    stamps_ns: Sequence[int] | NDArray[np.int64],
    options: MapOptions | None = None,
    *,
    diagnostics: dict[str, Any] | None = None,
) -> BuiltMap:
    """Paper Algorithm 1 over ``(summary, multiplicity)`` pairs (see the module docstring);
    ``stamps_ns`` are the trajectory's stamps (one per pose)."""
    built, _ = map_and_yields(samples, stamps_ns, options, diagnostics=diagnostics)
    return built


def map_and_yields(
    samples: Iterable[tuple[SampleSummary, float]],
    stamps_ns: Sequence[int] | NDArray[np.int64],
    options: MapOptions | None = None,
    *,
    diagnostics: dict[str, Any] | None = None,
) -> tuple[BuiltMap, list[frozenset[int]]]:
    """:func:`build_from_samples`, and for each sample (in the order given) the ids of the map's
    identities (objects and rejected) it yields: the indicators the chains' agreement is judged on."""
    options = options or MapOptions()
    identities: dict[frozenset[int], _Identity] = {}
    trajectories: list[tuple[NDArray[np.float64], float]] = []
    calibrations: list[tuple[SampleSummary, float]] = []
    total: float = 0
    yielded: list[set[frozenset[int]]] = []
    for summary, count in samples:
        yielded.append(set())
        if count <= 0:
            continue
        total += count
        trajectories.append((np.asarray(summary.map_T_base, dtype=float), float(count)))
        calibrations.append((summary, float(count)))
        for obj in summary.objects:
            entry = identities.setdefault(obj.identity, _Identity(obj.label))
            kept = not is_spurious(obj, options.spurious_location_stddev_m)
            entry.add(obj, float(count), kept)
            if kept:
                yielded[-1].add(obj.identity)
    if total == 0:
        raise MapBuildError("no samples to build a map from")
    if len({t.shape for t, _ in trajectories}) != 1 or trajectories[0][0].shape != (len(stamps_ns), 3):
        raise MapBuildError(f"sample trajectories must all be ({len(stamps_ns)}, 3)")

    if not 0.5 < options.identity_overlap <= 1.0:
        raise MapBuildError(f"identity_overlap must lie in (0.5, 1], got {options.identity_overlap}")
    rows = []
    groups, group_of = _group_identities(identities, options.identity_overlap)
    for k, (identity, entry) in enumerate(groups):
        probability = entry.weight[True] / total
        seen = (entry.weight[True] + entry.weight[False]) / total
        if probability > options.existence_threshold or seen >= options.report_min_fraction:
            rows.append((identity, entry, probability, k))
    rows.sort(key=lambda r: (-r[2], min(r[0])))
    map_id_of_group = {row[3]: number for number, row in enumerate(rows)}
    objects: list[MappedObject] = []
    rejected: list[MappedObject] = []
    for number, (identity, entry, probability, _) in enumerate(rows):
        mean, cov = entry.moments()
        mapped = MappedObject(
            id=number,
            label=entry.label,
            position_m=(float(mean[0]), float(mean[1]), float(mean[2])),
            size_m=(float(mean[3]), float(mean[4])),
            existence_probability=float(probability),
            position_covariance=tuple(tuple(float(v) for v in row) for row in cov[:3, :3]),
            size_covariance=tuple(tuple(float(v) for v in row) for row in cov[3:, 3:]),
            measurement_count=len(identity),
        )
        (objects if probability > options.existence_threshold else rejected).append(mapped)

    trajectory = _mean_trajectory(trajectories)
    poses = tuple(
        TrajectoryPose(stamp_ns=int(s), x_m=float(p[0]), y_m=float(p[1]), theta_rad=float(p[2]))
        for s, p in zip(stamps_ns, trajectory, strict=True)
    )
    info = dict(diagnostics or {})
    info.update(
        {
            "identities": len(identities),
            "identity_overlap": float(options.identity_overlap),
            "spurious_location_stddev_m": float(options.spurious_location_stddev_m),
            "existence_threshold": float(options.existence_threshold),
        }
    )
    calibration = _mean_calibration(calibrations)
    if calibration is not None:
        info["odometry_calibration"] = calibration
    built = BuiltMap(objects=tuple(objects), rejected=tuple(rejected), trajectory=poses, diagnostics=info)
    yields = [
        frozenset(map_id_of_group[g] for g in {group_of[i] for i in exact} if g in map_id_of_group) for exact in yielded
    ]
    return built, yields
