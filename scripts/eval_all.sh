#!/usr/bin/env bash
# The README's results table: every scenario x every data association, scored against ground truth.
#
#   scripts/eval_all.sh                      # all five scenarios, all four associations
#   SCENARIOS="small office" scripts/eval_all.sh
#   ASSOCIATIONS="greedy none oracle" scripts/eval_all.sh
#   SCENARIOS="office:7 loop:4" ASSOCIATIONS=sampler OUT=out/eval_seeds scripts/eval_all.sh
#                                            # other seeds: bags rendered as out/bags/office_7, ...
#   MAP_ARGS="--params out/no_screen.yaml" OUT=out/eval_no_screen scripts/eval_all.sh
#                                            # other mapper settings (passed to every objslam map)
#
# Renders the scenarios that are not bundled (twins, clutter, loop) into out/bags/ if
# missing, builds each map with `objslam map --association A` at default settings
# (6000 samples, 2500 burn-in, default seed) into $OUT/SCENARIO/A.yaml (log beside it),
# prints one `objslam eval` table per scenario (maps side by side) and last a markdown
# summary. Maps already in $OUT are reused: remove $OUT (default out/eval) for a fresh run.
# The sampler dominates the run time (minutes per scenario; loop is the longest).
set -eo pipefail
cd "$(dirname "$0")/.."
if ! command -v objslam >/dev/null 2>&1; then
  # shellcheck disable=SC1091
  source env.sh
fi
OUT="${OUT:-out/eval}"
SCENARIOS="${SCENARIOS:-small office twins clutter loop}"
ASSOCIATIONS="${ASSOCIATIONS:-sampler greedy none oracle}"

# A scenario is NAME (the bundled bag, or seed 1) or NAME:SEED (rendered with that seed).
bag_of() {
  case "$1" in
    small | office) echo "bags/$1" ;;
    *:*) echo "out/bags/${1%%:*}_${1##*:}" ;;
    *) echo "out/bags/$1" ;;
  esac
}

# The bags not bundled, rendered exactly so (same scenario and seed: byte-identical bag).
render() {
  local bag name seed
  bag="$(bag_of "$1")"
  [ -d "$bag" ] && return 0
  mkdir -p "$(dirname "$bag")"
  name="${1%%:*}"
  seed=1
  case "$1" in *:*) seed="${1##*:}" ;; esac
  objslam sim "$name" --out "$bag" --seed "$seed" --compressed
}

jsons=()
for scenario in $SCENARIOS; do
  render "$scenario"
  bag="$(bag_of "$scenario")"
  dir="$OUT/${scenario/:/_}"
  mkdir -p "$dir"
  maps=()
  labels=()
  for association in $ASSOCIATIONS; do
    map="$dir/$association.yaml"
    if [ ! -f "$map" ]; then
      echo "eval_all: $scenario / $association ..." >&2
      start=$(date +%s)
      # shellcheck disable=SC2086
      objslam map "$bag" --out "$map" --association "$association" ${MAP_ARGS:-} >"$dir/$association.log" 2>&1 || {
        echo "eval_all: objslam map failed, see $dir/$association.log" >&2
        exit 1
      }
      echo "eval_all: $scenario / $association done in $(($(date +%s) - start)) s" >&2
    fi
    maps+=("$map")
    labels+=("$association")
  done
  echo
  echo "### $scenario"
  objslam eval "${maps[@]}" --bag "$bag" --label "${labels[@]}" | tee "$dir/eval.txt"
  objslam eval "${maps[@]}" --bag "$bag" --label "${labels[@]}" --json >"$dir/eval.json"
  jsons+=("$dir/eval.json")
done

echo
echo "### Summary"
python scripts/eval_summary.py "${jsons[@]}"
