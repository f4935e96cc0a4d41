"""What every ``python -m <package>`` tool shares: one-line errors, exit status 2.

A safety product's tools never answer bad input with a traceback: argparse
errors, and every exception type a command declares as "the user's input was
bad", become one line on stderr naming the file, line or field, and exit 2.
So does an optional dependency that is not installed: the box installs only what
its product needs (setup.cfg's extras, docs/install.md), and a command that needs
more names the extra to install. Anything else is a bug and keeps its traceback.

Logs go through :mod:`logging` with one formatter (:func:`setup_logging`): one line
per record, ``level=... component=... event=...`` first, so a journal can filter them.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from typing import Callable, Iterable

from edge_runtime.errors import BAD_INPUT, CliError, LinkError

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130

OPTIONAL_MODULES = {
    "cv2": "OpenCV", "pymavlink": "pymavlink", "serial": "pyserial", "scipy": "SciPy",
    "matplotlib": "matplotlib", "tqdm": "tqdm", "sklearn": "scikit-learn", "scikit_posthocs": "scikit-posthocs",
    "torch": "PyTorch", "onnx": "onnx", "onnxscript": "onnxscript", "openvino": "OpenVINO",
    "numpy": "numpy", "onnxruntime": "onnxruntime", "can": "python-can", "cantools": "cantools",
    "e2e": "autosar-e2e",
}
"""Import name -> what to call it, for every third-party module a command may import. A missing
one of these is an install without the right extra, not a bug (any other missing module is)."""
BASE_MODULES = frozenset({"numpy", "onnxruntime", "can", "cantools", "e2e"})
"""What every install has (setup.cfg install_requires): a missing one needs the plain package."""
DEFAULT_DISTRIBUTION = "edge-safety"


class MissingExtraError(CliError):
    """An optional dependency the command needs is not installed."""


def missing_extra(error: ModuleNotFoundError, what: str, extra: str | None) -> MissingExtraError | None:
    """The one-line error for ``error`` if it is a known optional dependency, else None (a bug).

    ``what`` is the command that needs it and ``extra`` the setup.cfg extra that brings it."""
    top = (error.name or "").split(".")[0]
    if top not in OPTIONAL_MODULES:
        return None
    target = _distribution() if top in BASE_MODULES or not extra else f"{_distribution()}[{extra}]"
    return MissingExtraError(f"{what} needs {OPTIONAL_MODULES[top]} (module {top}): pip install '{target}'")


def _distribution() -> str:
    """The installed distribution that holds edge_runtime (the box's runtime wheel, or this
    repository's): its extras have the same names."""
    from importlib.metadata import packages_distributions

    return (packages_distributions().get("edge_runtime") or [DEFAULT_DISTRIBUTION])[0]


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit status 2."""

    def error(self, message: str):  # noqa: D401 - argparse's signature
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_BAD_INPUT)


def make_parser(prog: str, description: str) -> tuple[OneLineParser, argparse._SubParsersAction]:
    """A parser with required subcommands that all report errors in one line."""
    parser = OneLineParser(prog=prog, description=description)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=OneLineParser)
    return parser, sub


def add_module_commands(sub: argparse._SubParsersAction, package: str,
                        commands: Iterable[tuple[str, str, str]], extras: dict[str, str] | None = None) -> None:
    """Subcommands that live in their own module of ``package``: (name, module, help) each.

    The module defines ``add_arguments(parser)``, ``cmd(args) -> int`` and optionally
    ``BAD_INPUT`` (exception types meaning "the user's input was bad"); they land in the
    parsed arguments as ``func`` and ``bad_input``. ``extras`` names the setup.cfg extra
    each command needs (``extra`` in the parsed arguments). A command whose module cannot
    be imported for want of an optional dependency stays listed, and running it says which
    extra to install: the other commands keep working on a lean install."""
    for name, module, help_text in commands:
        extra = (extras or {}).get(name)
        try:
            mod = importlib.import_module(f".{module}", package)
        except ModuleNotFoundError as e:
            if missing_extra(e, name, extra) is None:
                raise
            # No option prefix: every argument (--help too) is taken, and running it says what to install.
            p = sub.add_parser(name, help=f"{help_text} (needs {OPTIONAL_MODULES[e.name.split('.')[0]]})",
                               prefix_chars="\0", add_help=False)
            p.add_argument("arguments", nargs="*")
            p.set_defaults(func=_raiser(e), bad_input=(), extra=extra)
            continue
        p = sub.add_parser(name, help=help_text)
        mod.add_arguments(p)
        p.set_defaults(func=mod.cmd, bad_input=tuple(getattr(mod, "BAD_INPUT", ())), extra=extra)


def _raiser(error: ModuleNotFoundError) -> Callable[[argparse.Namespace], int]:
    def cmd(args: argparse.Namespace) -> int:
        raise error

    return cmd


def run(func: Callable[[], int | None], bad_input: Iterable[type[BaseException]] = (),
        what: str = "this command", extra: str | None = None) -> int:
    """Run ``func``; exceptions in ``bad_input`` (and CliError) become one line + exit 2, and so
    does a missing optional dependency (naming ``extra``, the setup.cfg extra ``what`` needs)."""
    errors = (CliError, *bad_input)
    try:
        return int(func() or 0)
    except ModuleNotFoundError as e:
        missing = missing_extra(e, what, extra)
        if missing is None:
            raise
        return _one_line(missing)
    except errors as e:
        return _one_line(e)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _one_line(e: BaseException) -> int:
    print(f"error: {' '.join(str(e).split())}", file=sys.stderr)
    return EXIT_BAD_INPUT


def run_command(args: argparse.Namespace) -> int:
    """Run the subcommand ``args`` were parsed for (``args.func``, see :func:`add_module_commands`).

    One line and exit status 2 for the error tree's bad input (``errors.BAD_INPUT``), for
    the command's own ``BAD_INPUT``, and for a ``LinkError`` (a bus or line that cannot be
    opened is named in one line too, not shown as a traceback)."""
    setup_logging()
    return run(lambda: args.func(args), bad_input=(*BAD_INPUT, LinkError, *getattr(args, "bad_input", ())),
               what=getattr(args, "command", None) or "this command", extra=getattr(args, "extra", None))


class OneLineFormatter(logging.Formatter):
    """``level=WARNING component=edge_runtime.core.service event=notify_failed message...``: one
    line per record (newlines folded), the fields a journal filter greps for first. When the
    stream is the journal (``$JOURNAL_STREAM``) each line also starts with its syslog priority (``<4>``),
    which journald takes as the record's priority (``journalctl -p warning``)."""

    SYSLOG_PRIORITY = {logging.CRITICAL: 2, logging.ERROR: 3, logging.WARNING: 4, logging.INFO: 6, logging.DEBUG: 7}

    def __init__(self, journal: bool = False):
        super().__init__()
        self.journal = journal

    def format(self, record: logging.LogRecord) -> str:
        event = getattr(record, "event", None) or "log"
        text = record.getMessage()
        if record.exc_info:
            text += " | " + self.formatException(record.exc_info)
        line = f"level={record.levelname} component={record.name} event={event} {' | '.join(text.splitlines())}"
        if self.journal:
            line = f"<{self.SYSLOG_PRIORITY.get(record.levelno, 6)}>{line}"
        return line


def setup_logging(level: int = logging.INFO, stream=None) -> None:
    """The one log handler of a runtime process: :class:`OneLineFormatter` lines on stderr,
    ``level`` and up from the runtime's own loggers, warnings and up from the libraries'.
    Idempotent (a second call replaces the handler, e.g. for a test's stream)."""
    root = logging.getLogger()
    for h in [h for h in root.handlers if getattr(h, "edge_runtime", False)]:
        root.removeHandler(h)
    stream = stream or sys.stderr
    handler = logging.StreamHandler(stream)
    handler.edge_runtime = True
    handler.setFormatter(OneLineFormatter(journal=_is_journal(stream)))
    root.addHandler(handler)
    logging.getLogger("edge_runtime").setLevel(level)


def _number(s: str, cast, what: str, ok) -> float:
    try:
        v = cast(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not {what}: {s!r}") from None
    if not ok(v):
        raise argparse.ArgumentTypeError(f"must be {what}, got {s}")
    return v


def positive_float(s: str) -> float:
    """argparse type: a finite number > 0."""
    return _number(s, float, "a positive number", lambda v: 0 < v < float("inf"))


def positive_int(s: str) -> int:
    """argparse type: an integer >= 1."""
    return _number(s, int, "an integer of at least 1", lambda v: v >= 1)


def probability(s: str) -> float:
    """argparse type: a number in [0, 1]."""
    return _number(s, float, "a probability in [0, 1]", lambda v: 0.0 <= v <= 1.0)


def hex_signing_key(flag: str) -> Callable[[str], bytes]:
    """argparse type for a MAVLink 2 signing key given as 64 hex digits (the simulators' flags)."""
    from edge_runtime.core.serial_line import parse_signing_key

    def parse(s: str) -> bytes:
        try:
            return parse_signing_key(s, flag)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    return parse


def _is_journal(stream) -> bool:
    """Whether ``stream`` is systemd's journal: ``$JOURNAL_STREAM`` names its device and inode."""
    try:
        st = os.fstat(stream.fileno())
    except (AttributeError, OSError, ValueError):  # not a file (a test's StringIO)
        return False
    return os.environ.get("JOURNAL_STREAM") == f"{st.st_dev}:{st.st_ino}"
