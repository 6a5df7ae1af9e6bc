"""The pipeline's runs: prepared in one place (a Ray task of ``objslam map-batch``), run and
finished in another, to the map ``build_map`` gives."""

from __future__ import annotations

import pickle
import time

import pytest

from objslam_common.catalog import load_catalog
from objslam_mapper.config import MapperConfig
from objslam_mapper.inference.diagnostics import Stopwatch
from objslam_mapper.pipeline import build_map, prepare_run, run_prepared
from tests.objslam_mapper.association_scenes import simulate
from tests.objslam_mapper.inference.test_inference import QUICK


def test_resume_keeps_each_phase_and_starts_the_next_now():
    watch = Stopwatch()
    time.sleep(0.02)
    watch.lap("tracklets")
    took = watch.seconds("tracklets")
    time.sleep(0.1)  # the run travelled to another process, or waited for other runs
    watch.resume()
    watch.lap("sampling")
    assert watch.seconds("tracklets") == pytest.approx(took)
    assert watch.seconds("sampling") < 0.05


def test_a_run_prepared_and_pickled_maps_as_build_map_does():
    run = simulate()
    config, catalog = MapperConfig(sampler=QUICK), load_catalog()
    prepared = prepare_run(run.odometry, run.images, config, catalog, config.camera_mount)
    phases: list[str] = []
    (built,) = run_prepared([pickle.loads(pickle.dumps(prepared))], progress=lambda p, d, t: phases.append(p))
    alone = build_map(run.odometry, run.images, config, catalog)
    timings = built.diagnostics.pop("timings_s")
    del alone.diagnostics["timings_s"]
    assert built == alone
    assert built.diagnostics["odometry_messages"] == len(run.odometry)
    assert list(dict.fromkeys(phases)) == ["sampling", "mapping"]  # the tracklets were made before
    assert timings["total"] == pytest.approx(timings["tracklets"] + timings["sampling"] + timings["mapping"], abs=0.01)
