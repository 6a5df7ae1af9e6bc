"""Association inference on the real factor-graph target (synthetic scenes, no images)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from objslam_common.catalog import load_catalog
from objslam_common.geometry import between, wrap_angle
from objslam_mapper.config import ClutterConfig, DetectionConfig, MapperConfig, MoveConfig, SamplerConfig
from objslam_mapper.graph.conditional_evidence import object_evidence
from objslam_mapper.graph.initialization import initial_object
from objslam_mapper.graph.solver import solve
from objslam_mapper.inference.association import CLUTTER, Association, enumerate_associations
from objslam_mapper.inference.chain import MetropolisHastings
from objslam_mapper.inference.clutter import DISTRACTOR, INDEPENDENT, ClutterModel
from objslam_mapper.inference.detection import own_rate_log_likelihood, sightings
from objslam_mapper.inference.exact import ExactDistribution
from objslam_mapper.inference.infer import infer_map
from objslam_mapper.inference.screen import ProposalScreen
from objslam_mapper.inference.start import clear_start_objects, initial_association, recall_start_clutter
from objslam_mapper.inference.target import NO_OBJECT_LOG_EVIDENCE, OBJECT, AssociationTarget, TargetOptions, estimates
from objslam_mapper.inference.tracklets import Tracklet, tracklets_of_problem
from objslam_mapper.model.slice_model import bounds_of_cuts
from objslam_mapper.pipeline import build_map
from objslam_mapper.synthetic import SyntheticObject
from tests.objslam_mapper.association_scenes import (
    GREEN,
    POSTER_FRAMES,
    RED_A,
    RED_B,
    problem_of,
    simulate,
    with_poster,
)

# The scenes' slices come from within 3.5 m (association_scenes): the detector sees no farther.
QUICK = SamplerConfig(samples=500, burn_in=150, chains=1, detection=DetectionConfig(max_range_m=3.5))


@pytest.fixture(scope="module")
def scene():
    run = simulate()
    problem = problem_of(run)
    return run, problem, tracklets_of_problem(problem)


def test_the_scene_needs_association(scene):
    _run, _problem, chained = scene
    # Each red object is seen on the way out and again on the way back: two tracklets each.
    assert sorted(chained.labels) == ["green", "red", "red", "red", "red"]


def test_odometry_chain_alone_has_zero_log_evidence(scene):
    """NO_OBJECT_LOG_EVIDENCE: the Jacobian from poses to (first-pose residual, increments)
    has determinant 1, so log|Lambda| is the sum of the factors' log-informations and the
    Laplace evidence of the odometry chain is 0 (checked by finite differences)."""
    _run, problem, _ = scene
    poses = np.array(problem.odometry_poses[:12])
    stddev = np.vstack([problem.first_pose_stddev, problem.increment_stddev[:11]])

    def residuals(flat):
        p = flat.reshape(-1, 3)
        rows = [p[0] - poses[0]] + [between(p[i - 1], p[i]) for i in range(1, len(p))]
        out = np.array(rows)
        out[:, 2] = wrap_angle(out[:, 2])
        return (out / stddev).ravel()

    x0 = poses.ravel()
    jac = np.column_stack([(residuals(x0 + h) - residuals(x0 - h)) / 2e-6 for h in 1e-6 * np.eye(len(x0))])
    log_det_information = np.linalg.slogdet(jac.T @ jac)[1]
    log_normalizers = -0.5 * np.sum(np.log(2 * np.pi) + 2 * np.log(stddev))
    evidence = log_normalizers + 0.5 * len(x0) * np.log(2 * np.pi) - 0.5 * log_det_information
    assert evidence == pytest.approx(NO_OBJECT_LOG_EVIDENCE, abs=1e-5)


def test_target_is_the_graph_evidence_with_distractors_plus_the_clutter_terms(scene):
    """A clutter tracklet explained by a distractor is a group of the graph, with the broad
    distractor priors; one explained by independent false alarms is outside it."""
    _run, problem, chained = scene
    clutter = ClutterConfig()
    model = ClutterModel(problem, clutter)
    # Every tracklet its own object below: duplicates the no-overlap term would penalize (tested apart).
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=clutter, exclusion=False))
    members = [np.asarray(t.measurement_indices) for t in chained.tracklets]
    green = chained.labels.index("green")
    assert target.component(green).kind == DISTRACTOR  # a real object's tracklet fits a static thing
    state = Association.of([CLUTTER if t == green else t for t in range(len(members))])
    objects = [m for t, m in enumerate(members) if t != green]
    rows = [int(problem.measurement_label[m[0]]) for m in objects] + [model.distractor_row(int(members[green][0]))]
    graph = solve(model.problem, [*objects, members[green]], priors=rows)
    assert target(state) == pytest.approx(graph.log_evidence + np.log(clutter.distractor_weight), abs=1e-6)
    # Its map holds the objects only; the distractor is no map object.
    assert len(target.summary(state).objects) == len(objects)
    # Independent false alarms instead (the distractor switched off): outside the graph.
    off = dataclasses.replace(clutter, distractor_weight=0.0)
    target_off = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=off, exclusion=False))
    independent = len(members[green]) * off.log_likelihood_per_slice
    assert target_off(state) == pytest.approx(solve(problem, objects).log_evidence + independent, abs=1e-6)
    all_clutter = Association.of([CLUTTER] * len(members))
    assert target_off(all_clutter) == pytest.approx(sum(len(m) for m in members) * off.log_likelihood_per_slice)


def test_each_tracklet_takes_the_likelier_clutter_component(scene):
    _run, problem, chained = scene
    members = list(chained.tracklets[0].measurement_indices)
    config = ClutterConfig(distractor_weight=0.25)
    model = ClutterModel(problem, config)
    independent = len(members) * config.log_likelihood_per_slice
    fit = model.distractor_fit(members)
    distractor = fit.solution.log_evidence
    component = model.component(members)
    assert not fit.unlike_class and not component.unlike_class  # a real object's tracklet: shaped like its class
    assert component.kind == DISTRACTOR
    assert component.alone_log_likelihood == pytest.approx(np.log(0.25) + distractor)
    assert component.alone_log_likelihood > np.log(0.75) + independent
    # Its misses as a static thing alone count in the choice: priced above what its slices are
    # worth over false alarms, they make it independent false alarms.
    margin = np.log(0.25) + distractor - (np.log(0.75) + independent)
    priced = model.component(members, lambda f: -(margin - 1.0))
    assert priced.kind == DISTRACTOR and priced.alone_log_likelihood == pytest.approx(np.log(0.75) + independent + 1.0)
    assert model.component(members, lambda f: -(margin + 1.0)).kind == INDEPENDENT
    off = ClutterModel(problem, dataclasses.replace(config, distractor_weight=0.0)).component(members)
    assert off.kind == INDEPENDENT and off.log_weight == pytest.approx(independent)
    # Slices of nothing consistent (drawn uniformly from the measurement space): independent false alarms.
    rng = np.random.default_rng(0)
    noise = np.array(problem.measurements)
    bottom, top = np.sort(rng.uniform(-0.6, 0.6, (2, len(members))), axis=0)
    noise[members] = np.column_stack(
        [rng.uniform(-np.pi, np.pi, len(members)), rng.uniform(0.02, 0.5, len(members)), bottom, top]
    )
    scattered = ClutterModel(dataclasses.replace(problem, measurements=noise), config).component(members)
    assert scattered.kind == INDEPENDENT
    assert scattered.log_weight == pytest.approx(np.log(0.75) + independent)
    # A real object's tracklet is better explained by its class than by a shapeless distractor.
    assert solve(problem, [members]).log_evidence > distractor > independent


def test_a_distractor_under_the_floor_pays_for_it(scene):
    """With the camera believed lower than it is, a floor object's slices put a distractor's
    base under the floor (what a map grown about the camera does to every thing): the floor
    factor makes that cost, and costs next to nothing where the base is on the floor."""
    _run, problem, chained = scene
    members = list(chained.tracklets[chained.labels.index("green")].measurement_indices)
    config = ClutterConfig()
    no_floor = dataclasses.replace(config, distractor_floor_stddev_m=0.0)
    lowered = dataclasses.replace(
        problem, mount=dataclasses.replace(problem.mount, height_m=0.6 * problem.mount.height_m)
    )
    sunk = ClutterModel(lowered, no_floor).distractor_fit(members).solution
    assert sunk.objects[0].location_m[2] < -0.1
    held = ClutterModel(lowered, config).distractor_fit(members).solution
    # Held up (and nearer), at a price: the slices pin the base relative to the camera.
    assert held.objects[0].location_m[2] > sunk.objects[0].location_m[2] + 0.02
    assert held.log_evidence < sunk.log_evidence - 10.0
    on_floor = [ClutterModel(problem, c).distractor_fit(members).solution.log_evidence for c in (config, no_floor)]
    assert on_floor[0] == pytest.approx(on_floor[1], abs=1.0)


def test_a_static_thing_seen_in_two_of_the_images_facing_it_is_false_alarms(scene):
    """The choice of clutter component prices a distractor's misses: two slices of a real
    object (its tracklet's first and last) fit a static thing, but alone they would miss in
    every image between, so they are independent false alarms. With the rest of that
    tracklet among the tracklets (fragments of one thing), the images the rest has a slice
    in over the pair's predicted bearing are no misses, and the pair stays a distractor."""
    _run, problem, chained = scene
    whole, others = chained.tracklets[0], list(chained.tracklets[1:])
    n = len(whole)

    def part(ks: list[int]) -> Tracklet:
        return Tracklet(
            whole.label,
            tuple(whole.measurement_indices[k] for k in ks),
            tuple(whole.frame_indices[k] for k in ks),
            whole.position_xy_m,
        )

    pair, rest = part([0, n - 1]), part(list(range(1, n - 1)))
    detection = DetectionConfig(max_range_m=3.5)
    off = dataclasses.replace(detection, enabled=False)
    lonely = AssociationTarget(problem, [pair, *others], TargetOptions(detection=detection))
    assert AssociationTarget(problem, [pair, *others], TargetOptions(detection=off)).component(0).kind == DISTRACTOR
    assert lonely.component(0).kind == INDEPENDENT
    fit = lonely.clutter.distractor_fit(list(pair.measurement_indices))
    seen = sightings(
        lonely.problem,
        fit.solution.map_T_base,
        estimates(fit.solution),
        [np.array(pair.measurement_indices)],
        detection,
        lonely.view,
    )
    assert np.count_nonzero(seen.missed) >= n - 2  # what it would pay alone as a distractor
    # In clutter it is then outside the graph and pays no misses.
    in_clutter = Association.of([CLUTTER, *range(len(others))])
    assert all(g[0] == "object" for g in lonely.graph_groups(in_clutter))
    beside = AssociationTarget(problem, [pair, rest, *others], TargetOptions(detection=detection))
    assert beside.component(0).kind == DISTRACTOR and beside.component(1).kind == DISTRACTOR


def test_which_distractors_share_hits_is_fixed_per_thing_not_by_the_state():
    """The poster's tracklet shares its hits in every state where it is clutter, a real object's
    never, however the rest of the map moves (a stretched map must not make things unlike);
    tracklets that are one thing share if their slices together fit a thing unlike the class."""
    run = simulate()
    problem = problem_of(run, with_poster(run))
    chained = tracklets_of_problem(problem)
    options = TargetOptions(clutter=ClutterConfig(), exclusion=False)
    target = AssociationTarget(problem, chained.tracklets, options)
    model = target.clutter
    flags = [model.component(list(t.measurement_indices)).unlike_class for t in chained.tracklets]
    assert any(flags) and not all(flags)
    unlike = _unlike_of(model, chained.tracklets, flags)
    n = len(chained.tracklets)
    states = [Association.of([CLUTTER] * n), Association.of(list(range(n)))]
    states += [Association.of([CLUTTER if t == k else t for t in range(n)]) for k in range(n)]
    # One object of two tracklets of a class, the rest clutter: where the pair is two objects'
    # tracklets, the map bends, and at its estimates other red tracklets looked unlike their class.
    labels = chained.labels
    states += [
        Association.of([0 if t in (a, b) else CLUTTER for t in range(n)])
        for a in range(n)
        for b in range(a + 1, n)
        if labels[a] == labels[b]
    ]
    for state in states:
        groups = target.graph_groups(state)
        expected = [
            model.distractor_row(int(chained.tracklets[g[1][0]].measurement_indices[0]))
            if g[0] == DISTRACTOR and unlike(g[1])
            else -1
            for g in groups
        ]
        assert list(target.kin(groups)) == expected


def _unlike_of(model: ClutterModel, tracklets, flags):
    def unlike(thing: tuple[int, ...]) -> bool:
        if len(thing) == 1:
            return flags[thing[0]]
        return model.distractor_fit(sorted(m for t in thing for m in tracklets[t].measurement_indices)).unlike_class

    return unlike


def _split(tracklet: Tracklet, at: int) -> tuple[Tracklet, Tracklet]:
    """A tracklet cut in two where the chaining lost it for an image (same rough position)."""
    return (
        dataclasses.replace(
            tracklet, measurement_indices=tracklet.measurement_indices[:at], frame_indices=tracklet.frame_indices[:at]
        ),
        dataclasses.replace(
            tracklet, measurement_indices=tracklet.measurement_indices[at:], frame_indices=tracklet.frame_indices[at:]
        ),
    )


@pytest.mark.parametrize("label", ["red", "green"])
def test_a_thing_cut_into_tracklets_is_worth_what_it_is_in_one(scene, label):
    """Clutter tracklets that are one thing are one distractor (AssociationTarget.joins): a
    tracklet cut in two has, in every state that keeps its halves together (one object, or
    both clutter), the value the whole tracklet has. As two distractors (each its Occam factor,
    its weight and the misses of the images only the other saw) clutter was dearer for a thing
    seen in fragments, and patches became objects."""
    _run, problem, chained = scene
    whole = list(chained.tracklets)
    k = max(range(len(whole)), key=lambda t: (whole[t].label == label, len(whole[t])))
    cut = [*whole[:k], *_split(whole[k], len(whole[k]) // 2), *whole[k + 1 :]]
    options = TargetOptions(clutter=ClutterConfig(), exclusion=False, detection=DetectionConfig(max_range_m=3.5))
    split_target = AssociationTarget(problem, cut, options)
    whole_target = AssociationTarget(problem, whole, options)
    assert k + 1 in split_target.joins()[k]
    n = len(whole)
    for rest in (CLUTTER, "own"):
        labels = [CLUTTER if rest == CLUTTER else t for t in range(n)]
        for halves in (CLUTTER, n):  # both clutter, or both one object
            whole_labels = [*labels[:k], halves, *labels[k + 1 :]]
            cut_labels = [*labels[:k], halves, halves, *labels[k + 1 :]]
            whole_state, cut_state = Association.of(whole_labels), Association.of(cut_labels)
            assert split_target(cut_state) == pytest.approx(whole_target(whole_state), abs=1e-6)
    all_clutter = split_target.graph_groups(Association.of([CLUTTER] * (n + 1)))
    assert len(all_clutter) == len(whole_target.graph_groups(Association.of([CLUTTER] * n)))


def test_tracklets_of_different_things_are_not_one_thing(scene):
    """Two red objects 0.8 m apart, each seen on the way out and back: with the odometry alone a
    pass of one joins both passes of the other (AssociationTarget.joins is judged in pairs), but
    where whole objects are clutter, each is one thing of its own tracklets. (Where only one
    pass of each is, those two may be gathered: a limit of judging with the odometry alone.)"""
    run, problem, chained = scene
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=ClutterConfig(), exclusion=False))
    true_object = {int(m): k for k, group in enumerate(run.groups(problem)) for m in group}
    truth = [true_object[t.measurement_indices[0]] for t in chained.tracklets]
    n = len(truth)
    objects = sorted(set(truth))
    states = [
        Association.of([CLUTTER if mask >> truth[t] & 1 else t for t in range(n)]) for mask in range(1 << len(objects))
    ]
    gathered = set()
    for state in states:
        for thing in target.clutter_things(state):
            assert len({truth[t] for t in thing}) == 1, (state, thing)
            gathered.add(thing)
    assert sum(len(thing) > 1 for thing in gathered) == 2  # both objects' passes, as one thing each
    assert any(truth[a] != truth[b] for a in range(n) for b in target.joins()[a])  # the chain is there


def test_a_distractor_explains_a_floating_poster_far_better_than_its_class():
    run = simulate()
    problem = problem_of(run, with_poster(run))
    poster = [m for m in range(problem.measurement_count) if problem.measurement_image[m] in POSTER_FRAMES]
    poster = [m for m in poster if problem.measurement_slot[m] == len(run.images[problem.measurement_image[m]].slices)]
    assert len(poster) == len(POSTER_FRAMES)
    model = ClutterModel(problem, ClutterConfig())
    fit = model.distractor_fit(poster)
    distractor = fit.solution.log_evidence
    assert fit.unlike_class and model.component(poster).unlike_class
    # Its class explains the poster's slices only as outliers (objslam_mapper.model.outliers).
    assert distractor > solve(problem, [poster]).log_evidence + 40.0


@pytest.mark.slow
def test_chain_on_the_real_target_matches_its_exact_distribution(scene):
    """Every association of the scene's tracklets solved by the factor graph, then tempered
    (log target / 20) so that more than a handful of states carry mass."""
    _run, problem, chained = scene
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=ClutterConfig(), max_iterations=15))
    states = enumerate_associations(chained.labels)
    tempered = {s: target(s) / 20.0 for s in states}
    exact = ExactDistribution.of(states, tempered.__getitem__)
    assert exact.probabilities.max() < 0.9
    sampler = MetropolisHastings(
        chained.labels,
        tempered.__getitem__,
        positions_xy_m=[t.position_xy_m for t in chained.tracklets],
        tracklet_weights=[len(t) for t in chained.tracklets],
    )
    result = sampler.run(initial_association(chained.tracklets, 0.6), 40_000, 1000, 3, keep_trace=False)
    assert exact.total_variation(result.counts) < 0.05


def _near(obj, truth, tolerance_m):
    return np.hypot(obj.position_m[0] - truth.location_m[0], obj.position_m[1] - truth.location_m[1]) < tolerance_m


def test_two_objects_of_one_class_08_m_apart_stay_two_objects(scene):
    _run, problem, _ = scene
    built = infer_map(problem, QUICK)
    reds = [o for o in built.objects if o.label == "red"]
    assert len(reds) == 2 and len(built.objects) == 3
    assert any(_near(o, RED_A, 0.15) for o in reds) and any(_near(o, RED_B, 0.15) for o in reds)
    assert all(o.existence_probability > 0.5 for o in built.objects)
    assert built.diagnostics["chain_runs"][0]["start_objects"] > 3  # the sampler, not the start state, joined them


def test_a_poster_seen_from_a_few_poses_does_not_become_an_object():
    run = simulate()
    problem = problem_of(run, with_poster(run))
    # The green object is in place once the loop closes: a red tracklet joins the object it
    # left (+38 nats for the target, -434 for the screen at fixed poses, so only its floor
    # lets it through, and informed moves cannot find it either). 500 steps found it for 11
    # of 12 seeds.
    built = infer_map(problem, dataclasses.replace(QUICK, samples=1500, burn_in=500))
    greens = [o for o in built.objects if o.label == "green"]
    plain = tracklets_of_problem(problem_of(run))
    green_slices = sum(len(t) for t in plain.tracklets if t.label == "green")
    assert len(greens) == 1 and _near(greens[0], GREEN, 0.2)
    assert greens[0].measurement_count == green_slices  # the poster's slices are not in it
    assert not any(np.hypot(o.position_m[0] - 3.0, o.position_m[1] + 2.5) < 1.0 for o in built.objects)
    assert built.diagnostics["chain_runs"][0]["best_state_clutter_tracklets"] == 1


def test_build_map_runs_the_pipeline_deterministically():
    run = simulate()
    phases = []
    maps = [
        build_map(
            run.odometry, run.images, MapperConfig(sampler=QUICK), load_catalog(), lambda p, d, t: phases.append(p)
        )
        for _ in range(2)
    ]
    for built in maps:
        del built.diagnostics["timings_s"]
    assert maps[0] == maps[1]
    assert list(dict.fromkeys(phases)) == ["tracklets", "sampling", "mapping"]
    built = maps[0]
    assert len(built.trajectory) == len(run.images)
    assert [p.stamp_ns for p in built.trajectory] == [im.stamp_ns for im in run.images]
    assert np.abs(built.trajectory_array()[:, :2] - run.true_map_T_base[:, :2]).max() < 0.3
    diagnostics = built.diagnostics
    for key in ("samples", "burn_in", "chain_runs", "convergence", "tracklets", "graph_poses"):
        assert key in diagnostics
    for key in ("start", "acceptance_rates", "distinct_associations_visited", "best_log_target", "trace"):
        assert key in diagnostics["chain_runs"][0]
    assert diagnostics["samples"] == 500 and diagnostics["kept_samples"] == 350


def test_initial_association_joins_near_tracklets_of_one_class_seen_apart():
    def tracklet(label, frames, xy):
        return Tracklet(label, tuple(range(frames[0], frames[1])), tuple(range(frames[0], frames[1])), xy)

    tracklets = [
        tracklet("red", (0, 5), (0.0, 0.0)),
        tracklet("red", (10, 15), (0.3, 0.0)),  # near the first, seen later: same object
        tracklet("red", (3, 8), (-0.1, -0.1)),  # near, but seen together with the first
        tracklet("green", (20, 25), (0.0, 0.1)),  # near, other class
        tracklet("red", (30, 35), (2.0, 0.0)),  # too far
    ]
    state = initial_association(tracklets, 0.6)
    assert state == Association.of([0, 0, 1, 2, 3])


def test_initial_association_leaves_the_given_tracklets_in_clutter():
    def tracklet(frames, xy):
        return Tracklet("red", tuple(range(*frames)), tuple(range(*frames)), xy)

    tracklets = [tracklet((0, 5), (0.0, 0.0)), tracklet((10, 15), (0.3, 0.0)), tracklet((20, 25), (0.2, 0.1))]
    assert initial_association(tracklets, 0.6, clutter={0}) == Association.of([CLUTTER, 0, 0])
    assert initial_association(tracklets, 0.6, clutter={0, 1, 2}) == Association.of([CLUTTER] * 3)


def test_a_floor_patch_prefers_clutter_and_starts_there_while_a_short_object_does_not():
    """A flat blue patch on the floor (0.18 m across) fits a blue cylinder (0.2 x 0.9 m) only
    with a height tens of prior stddevs off; a yellow object (0.5 x 0.3 m, as short as real
    objects get) fits its class. The target, alone with the odometry, tells them apart by a
    clear margin, and the start state of the chain follows it."""
    yellow = SyntheticObject("yellow", (2.5, 1.3, 0.0), (0.52, 0.29))
    patch = SyntheticObject("blue", (3.5, -1.2, 0.0), (0.18, 0.003))
    run = simulate((yellow, patch))
    problem = problem_of(run)
    chained = tracklets_of_problem(problem)
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=ClutterConfig()))
    assert set(chained.labels) == {"blue", "yellow"}
    for t, tracklet in enumerate(chained.tracklets):
        alone = solve(problem, [list(tracklet.measurement_indices)]).log_evidence
        margin = target.tracklet_clutter_log_likelihood(t) - alone
        if tracklet.label == "blue":
            assert margin > 20.0 and target.prefers_clutter(t)
        else:
            assert margin < -3.0 and not target.prefers_clutter(t)
    built = infer_map(problem, QUICK)
    assert built.diagnostics["chain_runs"][0]["start_clutter_tracklets"] == chained.labels.count("blue")
    assert [o.label for o in built.objects] == ["yellow"]


def test_sampler_config_validates():
    with pytest.raises(ValueError, match="burn_in"):
        dataclasses.replace(QUICK, burn_in=500)


def test_a_start_object_made_of_a_patch_seen_twice_is_cleared_to_clutter():
    """A floor patch near the start is seen on the way out and back: two tracklets that the
    start state joins into one object of its class. The target prefers all of it as
    clutter, and the start is moved there before the chain runs."""
    yellow = SyntheticObject("yellow", (2.5, 1.3, 0.0), (0.52, 0.29))
    patch = SyntheticObject("blue", (1.5, -1.2, 0.0), (0.18, 0.003))
    problem = problem_of(simulate((yellow, patch)))
    chained = tracklets_of_problem(problem)
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=ClutterConfig()))
    blue = [t for t, label in enumerate(chained.labels) if label == "blue"]
    assert len(blue) >= 2
    joined = Association.of([0 if t in blue else 1 for t in range(len(chained.labels))])
    cleared, moved = clear_start_objects(ProposalScreen(target), joined)
    assert moved == blue
    assert set(cleared.clutter) == set(blue) and cleared.n_objects == 1
    assert target(cleared) > target(joined)


def test_the_start_leaves_an_object_whose_clutter_would_be_shaped_like_its_class_to_the_chain():
    """Of the patch and the real object, only the patch is cleared, even with a target that
    prefers the real object in clutter too (as one drifting odometry may: a distractor's free
    size absorbs it): as clutter the object's tracklets would be distractors shaped like their
    class, and whether they are is the chain's question, not the start's."""
    yellow = SyntheticObject("yellow", (2.5, 1.3, 0.0), (0.52, 0.29))
    patch = SyntheticObject("blue", (1.5, -1.2, 0.0), (0.18, 0.003))
    problem = problem_of(simulate((yellow, patch)))
    chained = tracklets_of_problem(problem)

    class PrefersClutter(AssociationTarget):
        def __call__(self, state):
            return super().__call__(state) + 1000.0 * len(state.clutter)

    target = PrefersClutter(problem, chained.tracklets, TargetOptions(clutter=ClutterConfig()))
    blue = [t for t, label in enumerate(chained.labels) if label == "blue"]
    joined = Association.of([0 if t in blue else 1 for t in range(len(chained.labels))])
    all_clutter = Association.of([CLUTTER] * len(chained.labels))
    kinds = {
        chained.labels[th[0]]: (target.thing_component(th).kind, target.thing_component(th).unlike_class)
        for th in target.clutter_things(all_clutter)
    }
    assert kinds == {"yellow": (DISTRACTOR, False), "blue": (DISTRACTOR, True)}
    cleared, moved = clear_start_objects(ProposalScreen(target), joined)
    assert moved == blue and cleared.n_objects == 1


def test_start_tracklets_left_in_clutter_join_their_object_and_a_poster_stays():
    """The start left one red tracklet in clutter (as a short look alone may be): the greedy
    pass puts it into its object. The poster's tracklet is offered to the green object
    (within reach at 5 m) and stays clutter: the target prefers it there."""
    run = simulate()
    problem = problem_of(run, with_poster(run))
    chained = tracklets_of_problem(problem)
    target = AssociationTarget(
        problem, chained.tracklets, TargetOptions(clutter=ClutterConfig(), detection=QUICK.detection)
    )

    def owner(tracklet):
        m = tracklet.measurement_indices[0]
        image, slot = problem.measurement_image[m], problem.measurement_slot[m]
        return run.slice_object[image][slot] if slot < len(run.slice_object[image]) else CLUTTER

    truth = Association.of([owner(tr) for tr in chained.tracklets])
    poster = truth.clutter
    assert len(poster) == 1
    red = [t for t, tr in enumerate(chained.tracklets) if tr.label == "red"]
    left_out = max(red)  # a later look at one of the red objects
    start = Association.of([CLUTTER if t == left_out else a for t, a in enumerate(truth.assignment)])
    screen = ProposalScreen(target)
    recalled, moved = recall_start_clutter(screen, start, max_distance_m=5.0)
    assert moved == [left_out]
    assert recalled == truth and target(recalled) > target(start)
    # Already right: nothing moves.
    assert recall_start_clutter(screen, truth, max_distance_m=5.0) == (truth, [])


def test_the_screen_counts_the_misses_of_the_groups_a_move_changes():
    """At the screen's fixed poses and estimates its detection term is the change of the
    changed groups' misses (the kept groups' are the target's to count): a red object
    stands between the start and a green one that is in view from there (detection range
    10 m) but has slices only from within 3.5 m; taking the red object away is credited
    with the red object's misses, not charged with those the green one then has. The
    widths where the detection rate ramps are set wide, so that the changed groups' slices
    and misses at partial rates are in what the screen must get right."""
    blocker = SyntheticObject("red", (2.25, -0.65, 0.0), (0.3, 0.6))
    problem = problem_of(simulate((RED_A, GREEN, blocker)))
    chained = tracklets_of_problem(problem)
    detection = DetectionConfig(max_range_m=10.0, narrowest_width_rad=0.03, min_angular_width_rad=0.12)
    clutter = ClutterConfig(distractor_weight=0.0)  # clutter leaves the graph: nothing hides in its place
    target = AssociationTarget(
        problem, chained.tracklets, TargetOptions(clutter=clutter, exclusion=False, detection=detection)
    )
    state = initial_association(chained.tracklets, 0.6)
    screen = ProposalScreen(target)
    poses, _, estimates = screen._reference(state)
    old = target.graph_groups(state)
    kept_estimate = dict(zip(old, estimates, strict=True))

    def seen_as(groups, things):
        members = [target.measurements(g) for g in groups]
        return sightings(problem, poses, things, members, detection, target.view)

    def missed(groups, things):
        return dict(zip(groups, seen_as(groups, things).missed.sum(axis=0).tolist(), strict=True))

    def terms(groups, things):
        """Each group's detection term (none of them shares hits: each column on its own)."""
        seen = seen_as(groups, things)
        return {g: seen.terms(detection, [k]) for k, g in enumerate(groups)}

    before = terms(old, estimates)
    ramped = 0
    sampler = MetropolisHastings(
        chained.labels,
        target,
        MoveConfig(),
        positions_xy_m=[t.position_xy_m for t in chained.tracklets],
        tracklet_weights=[len(t) for t in chained.tracklets],
    )
    rng = np.random.default_rng(0)
    blocked = [t for t, tr in enumerate(chained.tracklets) if tr.label == "red" and tr.position_xy_m[1] < 0.0]
    moves = [Association.of([CLUTTER if t in blocked else a for t, a in enumerate(state.assignment)])]
    moves += [
        p.view.state
        for p in (sampler.proposals.propose(sampler.proposals.view(state), rng) for _ in range(30))
        if p is not None
    ]
    for new in moves:
        groups = target.graph_groups(new)
        things = np.array(
            [kept_estimate[g] if g in kept_estimate else screen._conditional(state, g)[1] for g in groups]
        )
        after = terms(groups, things)
        changed = sum(t.log_likelihood(detection) for g, t in after.items() if g not in before) - sum(
            t.log_likelihood(detection) for g, t in before.items() if g not in after
        )
        ramped += sum(t.width_log_likelihood != 0.0 for g, t in after.items() if g not in before)
        assert screen._screen_detection(state, old, groups) == pytest.approx(changed, abs=1e-9)
    assert ramped > 0
    # The blind spot: without the blocker the green object misses where it was hidden.
    green = next(g for g in old if chained.labels[g[1][0]] == "green")
    groups = target.graph_groups(moves[0])
    assert missed(groups, np.array([kept_estimate[g] for g in groups]))[green] > missed(old, estimates)[green]


def test_the_screen_solves_a_group_from_every_group_that_holds_its_slices():
    """A proposal that joins both looks at the red object near the start with the single
    look at a red object 5 m away: that look holds more slices than either of the others, and
    from its estimate the joined group converges there, the near slices beyond their caps,
    hundreds of nats below its optimum at the near object. The screen takes the best of the
    starts (each group that holds some of its slices; its own slices' start where none
    converges)."""
    far = SyntheticObject("red", (5.5, -2.8, 0.0), (0.30, 0.60))
    problem = problem_of(simulate((RED_A, GREEN, far)))
    chained = tracklets_of_problem(problem)
    target = AssociationTarget(problem, chained.tracklets, TargetOptions(clutter=ClutterConfig(distractor_weight=0.0)))
    red = [t for t, label in enumerate(chained.labels) if label == "red"]
    far_look = min(red, key=lambda t: np.hypot(*(chained.tracklets[t].position_xy_m - np.array(far.location_m[:2]))))
    near_looks = [t for t in red if t != far_look]
    sizes = {t: len(chained.tracklets[t]) for t in red}
    assert len(near_looks) == 2 and all(sizes[far_look] > sizes[t] for t in near_looks)
    assert sizes[far_look] < sum(sizes[t] for t in near_looks)
    state = Association.of(range(len(chained.tracklets)))  # every look its own object
    screen = ProposalScreen(target)
    poses, _, objects = screen._reference(state)
    group = (OBJECT, tuple(sorted(red)))
    members = target.measurements(group)
    row = target.prior_row(group, members)
    starts = [objects[state.assignment[t]] for t in red] + [initial_object(target.problem, members, poses)]
    evidence = [
        object_evidence(target.problem, poses, members, start, max_iterations=screen.iterations, prior=row)
        for start in starts
    ]
    from_far = evidence[red.index(far_look)].log_evidence
    log_evidence, estimate = screen._conditional(state, group)
    # The best of the starts, up to the solver's tolerance (starts in one basin stop apart).
    assert log_evidence == pytest.approx(max(e.log_evidence for e in evidence), abs=1e-2)
    assert log_evidence > from_far + 100.0
    assert np.hypot(*(estimate[:2] - np.array(RED_A.location_m[:2]))) < 0.1


def test_the_target_takes_upper_edges_as_measured_and_the_map_as_lower_bounds():
    problem = problem_of(simulate((RED_A, GREEN)))
    cut = np.zeros(problem.measurement_count, dtype=bool)
    cut[::2] = True
    # Every other upper edge was cut by the view, 0.05 rad below the object's: as measured they
    # pull the objects' tops down (the target's graph), as lower bounds they cost nothing (the map's).
    measured = np.array(problem.measurements)
    measured[cut, 3] -= 0.05
    censored = dataclasses.replace(
        problem, measurements=measured, measurement_bounds=bounds_of_cuts(np.zeros(cut.shape, int), cut)
    )
    chained = tracklets_of_problem(censored)
    target = AssociationTarget(censored, chained.tracklets, TargetOptions(clutter=ClutterConfig(distractor_weight=0.0)))
    assert not target.problem.measurement_bounds.any()
    np.testing.assert_array_equal(
        target.estimation_problem.measurement_bounds, bounds_of_cuts(np.zeros(cut.shape, int), cut)
    )
    state = initial_association(chained.tracklets, 0.6)
    summary = target.summary(state)
    groups = target.groups(state)
    as_bounds = solve(target.estimation_problem, groups)
    as_measured = target.solution(state)
    heights = [o.size_m[1] for o in summary.objects]
    np.testing.assert_allclose(heights, [o.size_m[1] for o in as_bounds.objects[: state.n_objects]], atol=1e-6)
    assert np.all(np.abs(np.subtract(heights, [o.size_m[1] for o in as_measured.objects[: state.n_objects]])) > 1e-3)


def test_the_target_keeps_edges_cut_at_the_sides_and_bottom_as_bounds():
    from objslam_common.records import CUT_BOTTOM, CUT_LEFT, CUT_TOP

    problem = problem_of(simulate((RED_A, GREEN)))
    cuts = np.zeros(problem.measurement_count, dtype=np.int64)
    cuts[::2] = CUT_LEFT | CUT_TOP
    cuts[1::4] = CUT_BOTTOM
    bounds = bounds_of_cuts(cuts, np.zeros(cuts.shape, bool))
    censored = dataclasses.replace(problem, measurement_bounds=bounds)
    chained = tracklets_of_problem(censored)
    target = AssociationTarget(censored, chained.tracklets, TargetOptions(clutter=ClutterConfig(distractor_weight=0.0)))
    expected = np.array(bounds)
    expected[:, 3] = 0  # only the upper edge is taken as measured
    np.testing.assert_array_equal(target.problem.measurement_bounds[: problem.measurement_count], expected)
    np.testing.assert_array_equal(target.estimation_problem.measurement_bounds[: problem.measurement_count], bounds)


def test_distractors_unlike_their_class_at_a_rate_of_their_own_in_the_target_and_the_screen():
    """With ``distractor_rate_prior`` set, a distractor unlike any object of its class (the
    poster, a metre above the floor class) is scored by the beta-binomial of its own hits and
    misses; objects, and a real object's tracklet as a distractor (shaped like its class: no
    escape from its misses), keep theirs at P_d. In the target, and in the screen over the
    groups a move changes at fixed poses."""
    run = simulate()
    problem = problem_of(run, with_poster(run))
    chained = tracklets_of_problem(problem)
    detection = DetectionConfig(max_range_m=10.0, distractor_rate_prior=2.0)
    options = TargetOptions(clutter=ClutterConfig(), exclusion=False, detection=detection)
    target = AssociationTarget(problem, chained.tracklets, options)

    def owner(tracklet):
        m = tracklet.measurement_indices[0]
        image, slot = problem.measurement_image[m], problem.measurement_slot[m]
        return run.slice_object[image][slot] if slot < len(run.slice_object[image]) else CLUTTER

    truth = Association.of([owner(tr) for tr in chained.tracklets])
    (poster,) = truth.clutter
    green = next(t for t, label in enumerate(chained.labels) if label == "green" and t != poster)
    to_clutter = Association.of([CLUTTER if t == green else a for t, a in enumerate(truth.assignment)])
    log_miss = np.log1p(-detection.probability)

    def counts(assoc, poses, things):
        """Each graph group's hits, misses and kin, from sightings made apart."""
        groups = target.graph_groups(assoc)
        members = [target.measurements(g) for g in groups]
        kin = target.kin(groups)
        seen = sightings(problem, poses, things, members, detection, target.view, kin=kin)
        should = seen.sight.in_view & ~seen.hidden
        hits, misses = (should & seen.hit).sum(axis=0), (should & ~seen.hit).sum(axis=0)
        return {g: (int(h), int(m), int(k)) for g, h, m, k in zip(groups, hits, misses, kin, strict=True)}

    def terms(assoc, poses, things):
        """Each graph group's detection term (own rates by hand)."""
        return {
            g: own_rate_log_likelihood(h, m, detection) if k >= 0 else m * log_miss
            for g, (h, m, k) in counts(assoc, poses, things).items()
        }

    for assoc in (truth, to_clutter):
        solution = target.solution(assoc)
        expected = sum(terms(assoc, solution.map_T_base, estimates(solution)).values())
        assert target.detection_log_likelihood(assoc, solution) == pytest.approx(expected, abs=1e-9)
    solution = target.solution(to_clutter)
    seen = counts(to_clutter, solution.map_T_base, estimates(solution))
    hits, misses, kin = seen[(DISTRACTOR, (poster,))]
    assert kin >= 0 and own_rate_log_likelihood(hits, misses, detection) > misses * log_miss + 1.0
    assert seen[(DISTRACTOR, (green,))][2] == -1
    # The screen: the change over the changed groups at the state's fixed poses and estimates.
    screen = ProposalScreen(target)
    poses, _, fixed_estimates = screen._reference(truth)
    old = target.graph_groups(truth)
    kept = dict(zip(old, fixed_estimates, strict=True))
    for new_state in (to_clutter, Association.of([0 if t == poster else a for t, a in enumerate(truth.assignment)])):
        new = target.graph_groups(new_state)
        things = np.array([kept[g] if g in kept else screen._conditional(truth, g)[1] for g in new])
        before, after = terms(truth, poses, fixed_estimates), terms(new_state, poses, things)
        changed = sum(v for g, v in after.items() if g not in before) - sum(
            v for g, v in before.items() if g not in after
        )
        assert screen._screen_detection(truth, old, new) == pytest.approx(changed, abs=1e-9)


def test_a_run_without_tracklets_maps_nothing_with_the_samplers_settings():
    """No slice chains into a tracklet: no chain runs, and the empty map still records the
    settings Algorithm 1 read (the sampler's, not the function's defaults)."""
    unseen = SyntheticObject("red", (60.0, 60.0, 0.0), (0.3, 0.6))  # beyond the camera's range
    problem = problem_of(simulate((unseen,)))
    assert problem.measurement_count == 0
    built = infer_map(problem, dataclasses.replace(QUICK, identity_overlap=0.9, existence_threshold=0.6))
    assert not built.objects and not built.rejected
    assert len(built.trajectory) == len(problem.stamps_ns)
    assert built.diagnostics["identity_overlap"] == 0.9 and built.diagnostics["existence_threshold"] == 0.6
