"""A seeded, bounded fuzzer for ``pursuit track`` inputs, track model files and experiment configs.

Not library API: a test tool.  ``python -m tests.fuzz --cases 2000 --seed 7`` runs it on demand
and prints a table of outcomes; ``tests/fuzz/test_fuzz.py`` runs a few hundred cases in the test
suite.  See ``docs/testing.md``.
"""
