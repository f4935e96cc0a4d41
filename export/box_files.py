"""The bundle's files for the box itself: ``install.sh``, the systemd units and their environment
files. ``@NAME@`` placeholders are filled by :func:`fill` (``export/bundle.py``, at build time) or
by ``install.sh`` (``@PREFIX@`` and ``@ETC@``, at install time: where the box puts things)."""
from __future__ import annotations

INSTALL_SH = r"""#!/bin/sh
# Installs this bundle (@PRODUCT@, @PLATFORM@, Python @PYTHON_VERSION@) without a package index:
# a venv at PREFIX with the runtime wheel and every dependency from wheels/ only, the shipped
# models checked against their manifest, the configuration and the systemd units.
#
#   ./install.sh [--prefix DIR] [--etc DIR] [--systemd DIR | --no-systemd] [--python PYTHON]
#
# Defaults: --prefix /opt/edge-safety, --etc /etc/edge-safety, --systemd /etc/systemd/system,
# --python python@PYTHON_VERSION@. An existing box.toml or *.env in --etc is kept.
set -eu
PREFIX=/opt/edge-safety
ETC=/etc/edge-safety
SYSTEMD=/etc/systemd/system
PYTHON=python@PYTHON_VERSION@
while [ $# -gt 0 ]; do
    case "$1" in
        --prefix) PREFIX=$2; shift 2 ;;
        --etc) ETC=$2; shift 2 ;;
        --systemd) SYSTEMD=$2; shift 2 ;;
        --no-systemd) SYSTEMD=; shift ;;
        --python) PYTHON=$2; shift 2 ;;
        *) echo "install.sh: unknown option: $1" >&2; exit 2 ;;
    esac
done
fail() { echo "install.sh: $*" >&2; exit 1; }
HERE=$(cd "$(dirname "$0")" && pwd)
cd "$HERE"
sha256sum --check --quiet SHA256SUMS || fail "files differ from SHA256SUMS: the bundle is damaged"
[ "$(uname -m)" = "@PLATFORM@" ] || fail "this bundle is for @PLATFORM@, this machine is $(uname -m)"
"$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != tuple(map(int, "@PYTHON_VERSION@".split("."))))' \
    || fail "$PYTHON is not Python @PYTHON_VERSION@ (the wheels in wheels/ are built for it)"

# wheels/ is the only source: no index, and no pip configuration or environment adds one.
unset PIP_INDEX_URL PIP_EXTRA_INDEX_URL PIP_FIND_LINKS
export PIP_CONFIG_FILE=/dev/null PIP_NO_INDEX=1 PIP_DISABLE_PIP_VERSION_CHECK=1
"$PYTHON" -m venv "$PREFIX"
"$PREFIX/bin/python" -m pip install --quiet --no-compile --no-index --find-links "$HERE/wheels" \
    "$HERE/@WHEEL@@EXTRAS@"
# Bytecode for what the runtime can import (ProtectSystem=strict: it cannot write any later).
# pymavlink's ~70 dialect modules other than common are never imported: compiling them would
# add 46 MiB of bytecode to the robot box, so they stay source only.
"$PREFIX/bin/python" -m compileall -q -j 0 -x '@SKIP_COMPILE@' \
    "$("$PREFIX/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" > /dev/null
"$PREFIX/bin/python" -c '
from edge_runtime.core.manifest import ASSETS_DIR, verify_all
models = verify_all(ASSETS_DIR)["models"]
print(f"models: {len(models)} checked against manifest.json (sha256) in {ASSETS_DIR}")'
cmp -s "$HERE/assets/manifest.json" \
    "$("$PREFIX/bin/python" -c 'from edge_runtime.core.manifest import ASSETS_DIR; print(ASSETS_DIR)')/manifest.json" \
    || fail "the installed manifest.json differs from the bundle's assets/manifest.json"

mkdir -p "$ETC"
[ -e "$ETC/box.toml" ] || cp box.toml "$ETC/box.toml"
for env in systemd/*.env; do
    [ -e "$ETC/$(basename "$env")" ] || cp "$env" "$ETC/"
done
if [ -n "$SYSTEMD" ]; then
    mkdir -p "$SYSTEMD"
    for unit in systemd/*.service; do
        sed -e "s|@PREFIX@|$PREFIX|g" -e "s|@ETC@|$ETC|g" "$unit" > "$SYSTEMD/$(basename "$unit")"
    done
    echo "units in $SYSTEMD: systemctl daemon-reload && systemctl enable --now @UNITS@"
fi
echo "installed @PRODUCT@ into $PREFIX (configuration: $ETC/box.toml)"
"""

UNIT = """[Unit]
Description=Edge safety runtime: @WHAT@
After=network.target
# A safety function is never given up on: no start rate limit, a restart every RestartSec.
StartLimitIntervalSec=0

[Service]
# READY=1 comes from the first turn of the drive loop (model loaded, bus open); after that
# WATCHDOG=1 every WatchdogSec/2 from the loop itself, so a hung loop is killed and restarted.
Type=notify
NotifyAccess=main
WatchdogSec=@WATCHDOG_S@
TimeoutStartSec=60
Restart=on-failure
# The loop also ends, with status 0, when its sensor is gone for good (a disconnected IMU, a
# camera stream that ended): on a box that is a fault to recover from, not a request to stop.
RestartForceExitStatus=0
RestartSec=2
EnvironmentFile=@ETC@/@NAME@.env
ExecStart=@PREFIX@/bin/@NAME@ --config @ETC@/box.toml $EDGE_ARGS
SyslogIdentifier=@NAME@
DynamicUser=yes
SupplementaryGroups=dialout video
NoNewPrivileges=yes
ProtectSystem=strict
ProtectHome=yes

[Install]
WantedBy=multi-user.target
"""

UNITS = {
    "wearable": dict(NAME="edge-wearable", WHAT="wearable distraction alerts on the vehicle CAN bus",
                     # the wrist IMU's silence is an event of the loop (every 150 ms), so 2 s is generous
                     WATCHDOG_S="2",
                     ENV="# Arguments after --config (python -m edge_runtime wearable --help)\n"
                         "EDGE_ARGS=--imu serial:/dev/ttyUSB0 --quiet\n"),
    "robot": dict(NAME="edge-robot", WHAT="robot co-worker safety (hazard zones, commands to the arm)",
                  # the loop turns per camera frame: a camera silent this long restarts the runtime too
                  # (the arm was stopped by the loop's staleness check long before)
                  WATCHDOG_S="5",
                  ENV="# Arguments after --config (python -m edge_runtime robot --help)\n"
                      "EDGE_ARGS=--link can --camera 0 --pose-model /etc/edge-safety/pose.onnx "
                      "--calibration /etc/edge-safety/calibration.json --quiet\n"),
}


SKIP_COMPILE = r"pymavlink/dialects/v[12]0/(?!(common|__init__)\.py$)"
"""compileall -x: the MAVLink dialects the runtime never imports (it uses v20's common)."""


def fill(template: str, **values: str) -> str:
    for key, value in values.items():
        template = template.replace(f"@{key}@", value)
    return template
