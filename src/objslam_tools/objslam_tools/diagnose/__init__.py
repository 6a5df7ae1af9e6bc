"""Diagnostics behind ``objslam diagnose NAME``: measurements of the method on simulated bags.

Each is one module of this package, discovered like the benchmarks
(``objslam_tools.subcommands``): adding one touches no other file.
"""
