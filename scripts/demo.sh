#!/usr/bin/env bash
# The main job on the bundled bag: build the object-based map of bags/office, write the
# map YAML and the pictures under out/, and score the map against the ground truth.
# Run through `make demo`, which sets everything up first.
set -euo pipefail
cd "$(dirname "$0")/.."
BAG="${BAG:-bags/office}"
OUT="${OUT:-out/$(basename "$BAG")}"
mkdir -p "$OUT"

objslam map "$BAG" --out "$OUT/map.yaml" --force --figures "$OUT"
objslam eval "$OUT/map.yaml" --bag "$BAG"
echo
echo "demo: map written to $OUT/map.yaml; pictures in $OUT/"
