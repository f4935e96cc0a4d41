"""A lean install (setup.cfg's extras): a command that needs an optional dependency which is not
installed says, in one line and exit 2, which extra to install; the other commands keep working."""
import subprocess
import sys
import textwrap

import pytest

from edge_runtime import cli

# Run a module with some top-level packages made unimportable, as on an install without their extra.
BLOCKER = textwrap.dedent("""
    import runpy, sys
    blocked = set(sys.argv[1].split(","))
    class Blocker:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in blocked:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    sys.meta_path.insert(0, Blocker())
    module, sys.argv = sys.argv[2], [sys.argv[2], *sys.argv[3:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)
""")
NOT_IN_BASE = "cv2,pymavlink,serial,scipy,matplotlib,tqdm,sklearn,scikit_posthocs,torch,onnx,onnxscript"


def run_without(blocked: str, *argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCKER, blocked, *argv], capture_output=True, text=True,
                          timeout=120)


def test_a_missing_optional_module_names_the_extra():
    e = cli.missing_extra(ModuleNotFoundError("No module named 'cv2'", name="cv2"), "robot", "robot")
    assert isinstance(e, cli.MissingExtraError)
    assert str(e) == "robot needs OpenCV (module cv2): pip install 'edge-safety[robot]'"
    base = cli.missing_extra(ModuleNotFoundError(name="numpy.linalg"), "wearable", "serial-imu")
    assert str(base).endswith("pip install 'edge-safety'")  # numpy is in every install: no extra
    assert cli.missing_extra(ModuleNotFoundError(name="edge_runtime.nope"), "robot", "robot") is None


def test_run_makes_a_missing_extra_one_line_and_exit_2_but_a_missing_own_module_a_bug(capsys):
    def needs(name):
        def func():
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return func

    assert cli.run(needs("pymavlink.dialects"), what="wearable", extra="serial-imu") == cli.EXIT_BAD_INPUT
    assert capsys.readouterr().err == ("error: wearable needs pymavlink (module pymavlink): "
                                       "pip install 'edge-safety[serial-imu]'\n")
    with pytest.raises(ModuleNotFoundError):
        cli.run(needs("edge_runtime.wearable.gone"))


@pytest.mark.slow
@pytest.mark.parametrize("argv, message", [
    (("edge_runtime", "wearable", "--imu", "serial:/dev/null?unsigned=yes"),
     "level=WARNING component=edge_runtime.wearable.command event=imu_unsigned --imu serial:/dev/null is unsigned (unsigned=yes): any device on the line can inject or replay "
     "IMU samples\nerror: wearable needs pyserial (module serial): pip install 'edge-safety[serial-imu]'"),
    (("firmware_sim", "imu", "--help"),
     "error: firmware_sim imu needs pymavlink (module pymavlink): pip install 'edge-safety[sim]'"),
    (("export", "assets", "--seed", "0"), "error: export assets needs onnx (module onnx): pip install "
                                          "'edge-safety[train]'"),
])
def test_commands_without_their_extra_say_what_to_install(argv, message):
    r = run_without(NOT_IN_BASE, *argv)
    assert (r.returncode, r.stderr) == (2, message + "\n")


@pytest.mark.slow
@pytest.mark.parametrize("argv", [("firmware_sim", "can-hub", "--help"), ("export", "bundle", "--help"),
                                  ("edge_runtime", "robot", "--help"), ("edge_runtime", "--help")])
def test_the_base_install_runs_the_commands_that_need_no_extra(argv):
    r = run_without(NOT_IN_BASE, *argv)
    assert r.returncode == 0 and r.stderr == "" and "usage:" in r.stdout


@pytest.mark.slow
def test_a_command_imports_its_own_modules_only():
    """`python -m edge_runtime wearable ...` sets up the wearable command alone: the robot's
    modules (lifter, camera, link) are not imported at start-up; the bare table lists all."""
    from edge_runtime.__main__ import COMMANDS, build_parser

    def commands(parser):
        sub = next(a for a in parser._actions if a.dest == "command")
        return sorted(sub.choices)

    assert commands(build_parser("wearable")) == ["wearable"]
    assert commands(build_parser()) == sorted(c[0] for c in COMMANDS)
    r = subprocess.run([sys.executable, "-c", "import sys; from edge_runtime.__main__ import build_parser; "
                        "build_parser('wearable'); print(sorted(m for m in sys.modules if m.startswith("
                        "'edge_runtime.robot')))"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stderr
