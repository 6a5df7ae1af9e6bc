"""Verbs whose subcommands are discovered modules (``objslam bench TARGET``, ``objslam diagnose NAME``).

Each module of such a package that exposes ``DESCRIPTION`` (one line),
``add_arguments(parser)`` and ``run(args) -> int`` is a subcommand, named after the module
(``error_budget`` is ``error-budget``); adding one touches no other file. Modules whose name
starts with ``_`` are helpers and are not imported here: every ``objslam`` verb builds the
whole parser, so what a subcommand module imports at its top, every verb pays for.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from types import ModuleType


def discover(package: ModuleType) -> dict[str, ModuleType]:
    """The subcommand modules of ``package`` by name, sorted."""
    found = {}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        if hasattr(module, "run") and hasattr(module, "add_arguments"):
            found[info.name.replace("_", "-")] = module
    return found


def register_group(
    subparsers: argparse._SubParsersAction,
    verb: str,
    package: ModuleType,
    help_text: str,
    description: str,
    metavar: str = "NAME",
) -> None:
    """Add ``verb`` with one subcommand per discovered module of ``package``."""
    found = discover(package)
    parser = subparsers.add_parser(verb, help=help_text, description=f"{description}: {', '.join(found)}.")
    sub = parser.add_subparsers(dest="subcommand", metavar=metavar)
    sub.required = True
    for name, module in found.items():
        target = sub.add_parser(name, help=module.DESCRIPTION, description=module.DESCRIPTION)
        module.add_arguments(target)
        target.set_defaults(func=module.run)
