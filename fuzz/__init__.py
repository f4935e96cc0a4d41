"""The fuzz harness: every parser and frame decoder of the box driven with mutated inputs (issue 16).

Not part of the runtime wheel. ``python -m fuzz`` runs the targets in :mod:`fuzz.targets`
(one module each, interface in fuzz/README.md); :mod:`fuzz.harness` counts crashes,
silent acceptances and hangs.
"""
