"""Rewrite build-machine include paths baked into the ROS wheels' CMake exports.

The ros-jazzy-* wheels were built under /opt/python/cp311-cp311; their exported
targets name that interpreter's include directories, and CMake refuses a target
whose include path does not exist. Point them at this venv's own directories.
Idempotent: a second run finds nothing to change.
"""

import sys
import sysconfig
from pathlib import Path

import numpy

BUILD_PYTHON_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
BUILD_NUMPY_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def main() -> int:
    prefix = Path(sys.prefix)
    replacements = {
        BUILD_NUMPY_INCLUDE: numpy.get_include(),
        BUILD_PYTHON_INCLUDE: sysconfig.get_paths()["include"],
    }
    changed = 0
    for path in (prefix / "share").rglob("*.cmake"):
        text = path.read_text(errors="surrogateescape")
        new = text
        for old, repl in replacements.items():
            new = new.replace(old, repl)
        if new != text:
            path.write_text(new, errors="surrogateescape")
            changed += 1
    print(f"fix_cmake_exports: rewrote {changed} file(s) under {prefix / 'share'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
