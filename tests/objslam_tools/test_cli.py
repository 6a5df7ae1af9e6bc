"""The ``objslam`` command's parser: every verb builds it, so it must stay cheap to build."""

from __future__ import annotations

import json
import subprocess
import sys

from objslam_tools.cli import build_parser
from objslam_tools.commands import eval as eval_command
from objslam_tools.evaluate import DEFAULT_GATE_M

# Each takes a quarter second or more to import; a verb that needs one imports it when run.
HEAVY = ("scipy.stats", "scipy.optimize", "scipy.interpolate", "matplotlib", "gtsam", "ray", "rosbags.typesys")


def _modules_after(code: str) -> set[str]:
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    return set(json.loads(out))


def test_building_the_parser_imports_no_heavy_library():
    loaded = _modules_after("from objslam_tools.cli import build_parser\nbuild_parser()")
    assert not [name for name in HEAVY if name in loaded]
    # The check sees them: the scorer, which `objslam eval` imports when run, loads two.
    scorer = _modules_after("import objslam_tools.evaluate")
    assert {"scipy.stats", "scipy.optimize"} <= scorer


def test_help_shows_the_defaults_the_verbs_apply():
    assert eval_command.GATE_HELP_DEFAULT_M == DEFAULT_GATE_M
    parser = build_parser()
    args = parser.parse_args(["eval", "map.yaml", "--bag", "b"])
    assert args.gate is None  # run() takes the scorer's


def test_every_verb_is_registered():
    parser = build_parser()
    verbs = next(a for a in parser._actions if a.dest == "verb").choices
    expected = {"bench", "call", "detector", "diagnose", "echo", "eval", "eval-detector", "figures", "map"}
    assert expected | {"map-batch", "mapper", "params", "play", "results", "sim"} <= set(verbs)
