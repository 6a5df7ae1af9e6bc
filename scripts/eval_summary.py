"""Markdown summary of `objslam eval --json` outputs (one file per scenario), for scripts/eval_all.sh.

Usage: python scripts/eval_summary.py out/eval/*/eval.json
Targets (issue 5): precision >= 0.95, recall >= 0.90, median xy error <= 0.10 m, mean diameter and
height errors <= 0.05 m, ATE <= 0.5 x raw odometry ATE, no distractor as a map object.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def _fmt(value: float | None, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def _targets(m: dict) -> str:
    def ok(value, test) -> bool:
        return value is not None and test(value)

    checks = [
        ok(m["precision"], lambda v: v >= 0.95),
        ok(m["recall"], lambda v: v >= 0.90),
        ok(m["xy_error_median_m"], lambda v: v <= 0.10),
        ok(m["diameter_error_mean_m"], lambda v: v <= 0.05) and ok(m["height_error_mean_m"], lambda v: v <= 0.05),
        m["trajectory_ate_m"] is not None
        and m["odometry_ate_m"] is not None
        and m["trajectory_ate_m"] <= 0.5 * m["odometry_ate_m"],
        m["distractors_as_objects"] == 0,
    ]
    return f"{sum(checks)}/{len(checks)}"


def main(paths: list[str]) -> int:
    header = (
        "| scenario | association | objects (map/real) | precision | recall | median xy err [m] | mean diam err [m] "
        "| mean height err [m] | ATE / odom ATE [m] | distractors as objects | targets met | time [s] |"
    )
    print(header)
    print("|" + "|".join(["---"] * (header.count("|") - 1)) + "|")
    for path in paths:
        data = json.loads(Path(path).read_text())
        scenario = Path(path).parent.name
        for entry in data["maps"]:
            m = entry["metrics"]
            wall = entry.get("diagnostics", {}).get("wall_time_s")
            print(
                f"| {scenario} | {entry['name']} | {m['map_objects']}/{m['truth_objects']} "
                f"| {_fmt(m['precision'], '.2f')} | {_fmt(m['recall'], '.2f')} "
                f"| {_fmt(m['xy_error_median_m'], '.3f')} | {_fmt(m['diameter_error_mean_m'], '.3f')} "
                f"| {_fmt(m['height_error_mean_m'], '.3f')} "
                f"| {_fmt(m['trajectory_ate_m'], '.3f')} / {_fmt(m['odometry_ate_m'], '.3f')} "
                f"| {m['distractors_as_objects']} | {_targets(m)} | {_fmt(wall, '.0f')} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
