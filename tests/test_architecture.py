"""The package boundaries, checked over the real import graph of ``src/``.

- ``objslam_common`` (outside its ``ros`` subpackage) imports only the standard library,
  numpy and PyYAML (and the ament index, to find the installed config);
- the core (``objslam_mapper`` and ``objslam_detector``, outside their ``ros``
  subpackages) imports no rclpy, no message types, nothing from ``objslam_tools`` and
  nothing of ``objslam_common.ros``;
- the detector does not depend on the mapper;
- inside the mapper data flows downwards: ``model`` < ``graph`` < ``inference`` <
  ``pipeline`` < ``ros``;
- there is no import cycle between modules (imports inside functions count; those under
  ``if TYPE_CHECKING:`` do not).

Each rule is also run against a small tree that breaks it, so that a rule that can no
longer fail is noticed.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path
from typing import NamedTuple

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
FIRST_PARTY = ("objslam_common", "objslam_mapper", "objslam_detector", "objslam_tools", "objslam_msgs")
MESSAGE_PACKAGES = ("_msgs", "_srvs", "_interfaces")
MAPPER_LAYERS = ("model", "graph", "inference", "pipeline", "ros")  # lower first


class Import(NamedTuple):
    importer: str  # module that imports
    imported: str  # the module (or package) imported
    line: int


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _type_checking_lines(tree: ast.AST) -> set[int]:
    """Lines inside ``if TYPE_CHECKING:`` blocks."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def all_imports(src: Path) -> list[Import]:
    """Every import of every first-party module under ``src`` (``src/PKG/PKG/...``), resolved to
    the module imported where it is one (``from a import b`` with ``a.b`` a module)."""
    modules: dict[str, Path] = {}
    for package_dir in sorted(p for p in src.iterdir() if (p / p.name).is_dir()):
        modules.update(
            {module_name(path, package_dir): path for path in (package_dir / package_dir.name).rglob("*.py")}
        )
    found = []
    for name, path in sorted(modules.items()):
        tree = ast.parse(path.read_text(), filename=str(path))
        skipped = _type_checking_lines(tree)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(tree):
            if getattr(node, "lineno", None) in skipped:
                continue
            if isinstance(node, ast.Import):
                found += [Import(name, alias.name, node.lineno) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*parent, base] if base else parent)
                for alias in node.names:
                    candidate = f"{base}.{alias.name}"
                    found.append(Import(name, candidate if candidate in modules else base, node.lineno))
    return found


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def _is_message_type(module: str) -> bool:
    top = module.split(".")[0]
    return top.endswith(MESSAGE_PACKAGES) or top == "builtin_interfaces"


def _is_ros(module: str) -> bool:
    return module.split(".")[0] in ("rclpy", "rcl_interfaces") or _is_message_type(module)


def _is_core(module: str) -> bool:
    return any(_in(module, p) and not _in(module, f"{p}.ros") for p in ("objslam_mapper", "objslam_detector"))


STDLIB = set(sys.stdlib_module_names) | {"__future__"}
ALLOWED_IN_COMMON = ("numpy", "yaml", "ament_index_python")


def boundary_violations(imports: list[Import]) -> list[str]:
    """What breaks the rules of the module docstring (empty when nothing does)."""
    bad = []
    for imp in imports:
        top = imp.imported.split(".")[0]
        where = f"{imp.importer}:{imp.line} imports {imp.imported}"
        if _in(imp.importer, "objslam_common") and not _in(imp.importer, "objslam_common.ros"):
            allowed = (
                top in STDLIB or top in ("numpy", "yaml", "ament_index_python") or _in(imp.imported, "objslam_common")
            )
            if not allowed or _in(imp.imported, "objslam_common.ros"):
                bad.append(f"{where}: objslam_common outside ros/ imports only the standard library, numpy and yaml")
        if _is_core(imp.importer):
            if _is_ros(imp.imported) or _in(imp.imported, "objslam_common.ros"):
                bad.append(f"{where}: the core imports no rclpy or message types")
            if _in(imp.imported, "objslam_tools"):
                bad.append(f"{where}: the core imports nothing from the tools")
        if _in(imp.importer, "objslam_detector") and _in(imp.imported, "objslam_mapper"):
            bad.append(f"{where}: the detector does not depend on the mapper")
        if _in(imp.importer, "objslam_common") and top in FIRST_PARTY and top not in ("objslam_common", "objslam_msgs"):
            bad.append(f"{where}: objslam_common depends on no other objslam package")
        layer_from, layer_to = _mapper_layer(imp.importer), _mapper_layer(imp.imported)
        if layer_from is not None and layer_to is not None and layer_to > layer_from:
            bad.append(f"{where}: inside the mapper, {MAPPER_LAYERS[layer_from]} sits below {MAPPER_LAYERS[layer_to]}")
    return bad


def _mapper_layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "objslam_mapper" or len(parts) < 2 or parts[1] not in MAPPER_LAYERS:
        return None
    return MAPPER_LAYERS.index(parts[1])


def cycles(imports: list[Import]) -> list[list[str]]:
    """Strongly connected groups of more than one first-party module (Tarjan)."""
    graph: dict[str, set[str]] = {}
    for imp in imports:
        if imp.imported.split(".")[0] in FIRST_PARTY and imp.imported != imp.importer:
            graph.setdefault(imp.importer, set()).add(imp.imported)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_package_boundaries_hold():
    assert boundary_violations(all_imports(SRC)) == []


def test_no_module_imports_itself_through_others():
    assert cycles(all_imports(SRC)) == []


def test_the_checks_see_what_they_forbid(tmp_path):
    files = {
        "objslam_common/objslam_common/__init__.py": "",
        "objslam_common/objslam_common/geometry.py": "import scipy\n",
        "objslam_detector/objslam_detector/__init__.py": "",
        "objslam_detector/objslam_detector/detector.py": "from objslam_mapper.model import slice_model\n",
        "objslam_mapper/objslam_mapper/__init__.py": "",
        "objslam_mapper/objslam_mapper/model/__init__.py": "",
        "objslam_mapper/objslam_mapper/model/slice_model.py": "from objslam_mapper.graph import problem\n",
        "objslam_mapper/objslam_mapper/graph/__init__.py": "",
        "objslam_mapper/objslam_mapper/graph/problem.py": (
            "import rclpy\nfrom objslam_tools import bag\nfrom objslam_mapper.model import slice_model\n"
        ),
        "objslam_mapper/objslam_mapper/ros/__init__.py": "",
        "objslam_mapper/objslam_mapper/ros/node.py": "import rclpy\nfrom objslam_msgs.msg import Slice\n",
        "objslam_tools/objslam_tools/__init__.py": "",
        "objslam_tools/objslam_tools/bag.py": "",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    imports = all_imports(tmp_path)
    bad = "\n".join(boundary_violations(imports))
    assert "geometry:1 imports scipy" in bad
    assert "detector does not depend on the mapper" in bad
    assert "problem:1 imports rclpy: the core imports no rclpy" in bad
    assert "problem:2 imports objslam_tools.bag: the core imports nothing from the tools" in bad
    assert "model sits below graph" in bad
    assert "ros.node" not in bad  # the nodes may use ROS
    assert cycles(imports) == [["objslam_mapper.graph.problem", "objslam_mapper.model.slice_model"]]


@pytest.mark.parametrize("package", ["objslam_common", "objslam_mapper", "objslam_detector", "objslam_tools"])
def test_every_package_is_seen(package):
    assert any(_in(imp.importer, package) for imp in all_imports(SRC))


# -- named options instead of long positional lists ------------------------------------------

MAX_POSITIONAL = 6
FOREIGN_CALLS = ("cv2.", "np.", "numpy.", "logger.", "logging.", "scipy.", "gtsam.")


def long_positional_lists(src: Path) -> list[str]:
    """Functions of ours taking more than ``MAX_POSITIONAL`` positional parameters (self and
    cls not counted), and calls passing more than that many positionally to anything but a
    third-party library."""
    found = []
    for path in sorted(src.rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                names = [a.arg for a in node.args.posonlyargs + node.args.args]
                names = names[1:] if names and names[0] in ("self", "cls") else names
                if len(names) > MAX_POSITIONAL:
                    found.append(f"{path}:{node.lineno}: def {node.name} takes {len(names)} positional parameters")
            elif isinstance(node, ast.Call) and len(node.args) > MAX_POSITIONAL:
                callee = ast.unparse(node.func)
                if not callee.startswith(FOREIGN_CALLS):
                    found.append(f"{path}:{node.lineno}: {callee} called with {len(node.args)} positional arguments")
    return found


def test_no_long_positional_argument_lists():
    assert long_positional_lists(SRC) == []


def test_the_positional_check_sees_long_lists(tmp_path):
    (tmp_path / "m.py").write_text(
        "def f(a, b, c, d, e, g, h):\n    pass\n\n\nf(1, 2, 3, 4, 5, 6, 7)\ncv2.putText(1, 2, 3, 4, 5, 6, 7, 8)\n"
        "def ok(self, a, b, c, d, e, g, *, h=0):\n    pass\n"
    )
    found = long_positional_lists(tmp_path)
    assert len(found) == 2 and "def f takes 7" in found[0] and "f called with 7" in found[1]
