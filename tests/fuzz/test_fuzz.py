"""A short seeded run of every fuzz target (fuzz/README.md): 0 crashes, 0 silent acceptances, 0 hangs."""
from __future__ import annotations

import types

import pytest
from hypothesis import strategies as st

from fuzz.harness import SilentAcceptance, discover, run_target

TARGETS = discover()
INPUTS = 300
TIMEOUT_S = 60.0
"""Only a real endless loop is a hang here (the suite runs on shared, loaded machines)."""


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_target_survives_a_seeded_run(name):
    report = run_target(TARGETS[name], INPUTS, seed=16, timeout_s=TIMEOUT_S)
    assert report.inputs == INPUTS
    findings = "\n\n".join(f"{f.key} ({f.count} inputs)\n{f.traceback}\nfirst input: {f.example}" for f in report.findings)
    assert report.clean, findings


def test_the_harness_counts_each_outcome_and_keeps_distinct_tracebacks():
    def run(n: int) -> None:
        if n % 5 == 0:
            raise ValueError("documented refusal")
        if n % 5 == 1:
            raise KeyError(n)  # a crash
        if n % 5 == 2:
            raise SilentAcceptance("out of range")
        if n % 5 == 3:
            while True:  # a hang: interrupted by the per-input timer
                pass

    target = types.SimpleNamespace(NAME="fake", DOCUMENTED=(ValueError,), run=run,
                                   strategy=lambda: st.integers(0, 4))
    report = run_target(target, 60, seed=1, timeout_s=0.05)  # hypothesis stops once it has tried all 5
    assert report.inputs == 5 and not report.clean
    assert (report.refused, report.crashes, report.silent_acceptances, report.hangs) == (1, 1, 1, 1)
    assert {f.kind for f in report.findings} == {"crash", "silent", "hang"}
    assert all(f.key.count(":") >= 2 for f in report.findings)  # type and file:line
