"""``--imu sim``: the simulated wrist IMU as a live source, for development and demos.

The runtime never imports the simulator (a box does not carry it). Instead this
starts ``python -m firmware_sim imu --pty`` as a child process -- the same
MAVLink firmware that ``make demo`` runs -- and reads it through the ordinary
serial source, so ``--imu sim`` exercises exactly the path a real sensor takes:
pseudo-terminal, MAVLink 2 parsing, CRC, signing, gap and silence handling.

Options ride in the spec as a query string::

    sim                                  3 minutes of driving, seed 0
    sim?minutes=10&seed=4                another drive
    sim?csv=drive/imu.csv&speed=10      stream a recording, ten times faster than real time
    sim?key=@FILE | key=env:NAME         signed MAVLink 2 (firmware and runtime share the key)
    sim?drop=0.01&corrupt=0.002&nan_burst=0.001&saturate=2&stop_after=30&message=scaled
                                         the firmware's fault modes (see ``python -m firmware_sim imu -h``)

An unknown option, or a value the firmware refuses, is one line naming it.
"""
from __future__ import annotations

import importlib.util
import subprocess
import sys
import threading
from urllib.parse import parse_qsl

from edge_runtime.core.serial_line import read_signing_key
from edge_runtime.errors import InputError
from edge_runtime.wearable.mavlink_source import MavlinkImuSource, SourceStatus
from edge_runtime.wearable.sources import ImuParams

FIRMWARE_OPTIONS = ("minutes", "seed", "csv", "speed", "message", "key", "drop", "drop_burst", "corrupt",
                    "nan_burst", "saturate", "stop_after")
START_TIMEOUT_S = 30.0


class SimSourceError(InputError):
    """The simulated IMU could not be started; the message names the option or the cause."""


def parse_sim_spec(spec: str) -> dict[str, str]:
    """``sim?a=1&b=2`` -> {"a": "1", "b": "2"}; unknown options are refused."""
    kind, _, query = spec.partition("?")
    if kind != "sim":
        raise SimSourceError(f"--imu {spec}: expected sim[?option=value&...]")
    opts = dict(parse_qsl(query, keep_blank_values=True, strict_parsing=False))
    unknown = sorted(set(opts) - set(FIRMWARE_OPTIONS))
    if unknown:
        raise SimSourceError(f"--imu {spec}: unknown option {unknown[0]!r} (known: {', '.join(FIRMWARE_OPTIONS)})")
    return opts


def firmware_command(opts: dict[str, str]) -> list[str]:
    cmd = [sys.executable, "-m", "firmware_sim", "imu", "--pty", "--linger", "0.5"]
    for name, value in opts.items():
        flag = "--sign-key" if name == "key" else "--" + name.replace("_", "-")
        cmd += [flag, value]
    return cmd


class SimImuSource(MavlinkImuSource):
    """A :class:`MavlinkImuSource` on the pseudo-terminal of a simulated IMU child process."""

    def __init__(self, spec: str, silence_timeout_s: float = 0.15, range_mps2: float = ImuParams.range_mps2,
                 read_period_s: float = 0.0):
        opts = parse_sim_spec(spec)
        if importlib.util.find_spec("firmware_sim") is None:
            raise SimSourceError("--imu sim: the simulated IMU firmware (package firmware_sim) is not installed "
                                 "here; it ships with a development checkout. On a box use --imu serial:PATH")
        key = None
        if "key" in opts:
            try:
                key = read_signing_key(opts["key"], "--imu sim: key")
                opts = {**opts, "key": key.hex()}  # the simulated firmware (a development tool) takes hex
            except ValueError as e:
                raise SimSourceError(str(e)) from None
        self.proc = subprocess.Popen(firmware_command(opts), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, bufsize=1)
        path = self._first_line()
        try:
            super().__init__(path, signing_key=key, silence_timeout_s=silence_timeout_s, range_mps2=range_mps2,
                             read_period_s=read_period_s)
        except ValueError:
            self._stop_child()
            raise
        # the firmware's own log (start and end lines) goes to our stderr
        threading.Thread(target=self._relay_stderr, daemon=True).start()

    def blocks(self, duration_s: float | None = None):
        """As :meth:`MavlinkImuSource.blocks`; once the drive is over (the child has exited and
        the line fell silent) a final ``disconnected`` status ends the stream."""
        for event in super().blocks(duration_s):
            yield event
            if isinstance(event, SourceStatus) and event.state == "silent" and self.proc.poll() is not None:
                yield SourceStatus("disconnected", event.since_s, event.last_t_s)
                return

    def _first_line(self) -> str:
        box: list[str] = []
        reader = threading.Thread(target=lambda: box.append(self.proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(START_TIMEOUT_S)
        line = box[0].strip() if box else ""
        if not line:
            self._stop_child()
            err = (self.proc.stderr.read() or "").strip().splitlines()
            why = err[-1] if err else f"no pseudo-terminal path within {START_TIMEOUT_S:.0f} s"
            raise SimSourceError(f"--imu sim: the simulated IMU did not start: {why}")
        return line

    def _relay_stderr(self) -> None:
        for line in self.proc.stderr:
            sys.stderr.write(line)

    def _stop_child(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def close(self) -> None:
        super().close()
        self._stop_child()
