#!/usr/bin/env bash
# The README's results table: every scenario x every data association, scored against ground truth.
#
#   scripts/eval_all.sh                      # all five scenarios, all four associations
#   SCENARIOS="small office" scripts/eval_all.sh
#   ASSOCIATIONS="greedy none oracle" scripts/eval_all.sh
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

bag_of() {
  case "$1" in
    small | office) echo "bags/$1" ;;
    *) echo "out/bags/$1" ;;
  esac
}

# The scenarios not bundled, rendered exactly so (same scenario and seed: byte-identical bag).
render() {
  local bag
  bag="$(bag_of "$1")"
  [ -d "$bag" ] && return 0
  mkdir -p "$(dirname "$bag")"
  case "$1" in
    twins) objslam sim twins --out "$bag" --seed 1 --compressed ;;
    clutter) objslam sim clutter --out "$bag" --seed 1 --compressed ;;
    loop) objslam sim loop --out "$bag" --seed 1 --compressed ;;
    *) echo "eval_all: no bag for scenario $1 at $bag" >&2 && return 1 ;;
  esac
}

jsons=()
for scenario in $SCENARIOS; do
  render "$scenario"
  bag="$(bag_of "$scenario")"
  mkdir -p "$OUT/$scenario"
  maps=()
  labels=()
  for association in $ASSOCIATIONS; do
    map="$OUT/$scenario/$association.yaml"
    if [ ! -f "$map" ]; then
      echo "eval_all: $scenario / $association ..." >&2
      start=$(date +%s)
      objslam map "$bag" --out "$map" --association "$association" >"$OUT/$scenario/$association.log" 2>&1 || {
        echo "eval_all: objslam map failed, see $OUT/$scenario/$association.log" >&2
        exit 1
      }
      echo "eval_all: $scenario / $association done in $(($(date +%s) - start)) s" >&2
    fi
    maps+=("$map")
    labels+=("$association")
  done
  echo
  echo "### $scenario"
  objslam eval "${maps[@]}" --bag "$bag" --label "${labels[@]}" | tee "$OUT/$scenario/eval.txt"
  objslam eval "${maps[@]}" --bag "$bag" --label "${labels[@]}" --json >"$OUT/$scenario/eval.json"
  jsons+=("$OUT/$scenario/eval.json")
done

echo
echo "### Summary"
python scripts/eval_summary.py "${jsons[@]}"
