"""The guard that keeps ``make test-fast`` free of child processes (support/process_guard.py)."""
import pytest

INNER_TESTS = """
import os, subprocess, sys
import pytest

def test_unmarked_subprocess():
    subprocess.run([sys.executable, "-c", "pass"], check=True)

@pytest.fixture
def child():
    return subprocess.Popen([sys.executable, "-c", "pass"]).wait()

def test_unmarked_process_from_a_fixture(child):
    assert child == 0

def test_unmarked_posix_spawn():
    os.waitpid(os.posix_spawn(sys.executable, [sys.executable, "-c", "pass"], dict(os.environ)), 0)

@pytest.mark.slow
def test_marked():
    subprocess.run([sys.executable, "-c", "pass"], check=True)

def test_no_process(tmp_path):
    (tmp_path / "x").write_text("threads, files and sockets are fine")
"""


@pytest.mark.slow  # it starts processes itself (in the tests it runs)
def test_unmarked_tests_that_start_processes_fail(pytester):
    pytester.makeini("[pytest]\nmarkers =\n    slow: starts processes\n")
    pytester.makepyfile(test_inner=INNER_TESTS)
    result = pytester.runpytest_inprocess("-p", "support.process_guard", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=2, failed=2, errors=1)
    result.stdout.fnmatch_lines_random([
        "*test_unmarked_subprocess started 1 process(es) but is not marked @pytest.mark.slow*subprocess.Popen: *",
        "*test_unmarked_process_from_a_fixture started 1 process(es)*",
        "*test_unmarked_posix_spawn started 1 process(es)*os.posix_spawn: *",
    ])
