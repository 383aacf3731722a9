"""Benchmarks behind ``nsl bench NAME``: one module per benchmark.

Each module defines ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> dict``; the dict is printed as one JSON object with ``--json``
or as a table otherwise.  Ratios are always measured side by side in one run.
"""
