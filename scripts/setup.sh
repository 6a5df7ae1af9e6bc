#!/usr/bin/env bash
# Set up everything objslam needs, from nothing, and do nothing when it is already
# there: .venv with the pinned requirements, the CMake fix-ups for the ROS wheels, the
# colcon build of src/ into install/, and the `objslam` command in .venv/bin.
# Each step keeps a stamp and reruns only when its inputs changed.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
PYTHON="${PYTHON:-python3}"
STAMPS="$VENV/.objslam-stamps"

say() { printf 'setup: %s\n' "$*"; }

newer_than() {  # newer_than STAMP FILE... : true if STAMP is missing or older than any FILE
  local stamp="$1"; shift
  [ -f "$stamp" ] || return 0
  [ -n "$(find "$@" -newer "$stamp" -print -quit 2>/dev/null)" ]
}

# 1. Python environment with the pinned versions.
if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
mkdir -p "$STAMPS"
if newer_than "$STAMPS/requirements" requirements.txt; then
  say "installing requirements.txt into .venv (about a minute the first time)"
  "$VENV/bin/python" -m pip install --quiet --upgrade pip
  "$VENV/bin/python" -m pip install --quiet -r requirements.txt
  # The wheels' CMake exports name the include dirs of the machine that built them.
  "$VENV/bin/python" scripts/fix_cmake_exports.py
  rm -f "$STAMPS/colcon"
  touch "$STAMPS/requirements"
fi

# 2. colcon build of the workspace (the venv is the ROS prefix underneath it).
if newer_than "$STAMPS/colcon" src/*/package.xml src/*/setup.py src/*/setup.cfg \
    src/objslam_msgs/CMakeLists.txt src/objslam_msgs/msg src/objslam_msgs/srv config; then
  say "colcon build of src/ into install/"
  # shellcheck disable=SC1091
  source "$VENV/bin/activate"
  rm -rf build install
  CMAKE_PREFIX_PATH="$VENV" AMENT_PREFIX_PATH="$VENV" \
    colcon --log-base log build --base-paths src --symlink-install \
      --event-handlers console_direct- console_stderr- \
      --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF
  touch "$STAMPS/colcon"
fi

# 3. The `objslam` command in .venv/bin and the packages importable from .venv, pointing
#    at src/ so that edits take effect without a rebuild (the colcon install uses
#    symlinks for the same reason).
SITE="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
printf '%s\n' "$ROOT/src/objslam_common" "$ROOT/src/objslam_mapper" "$ROOT/src/objslam_detector" "$ROOT/src/objslam_tools" \
  > "$SITE/objslam_src.pth"
cat > "$VENV/bin/objslam" <<EOS
#!$VENV/bin/python
import sys
from objslam_tools.cli import main
sys.exit(main())
EOS
chmod +x "$VENV/bin/objslam"
