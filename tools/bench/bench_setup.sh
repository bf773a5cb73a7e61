#!/usr/bin/env bash
# Prepare the dev-only benchmark environment (used by `make bench`):
#  * .venv-bench, a venv with requirements-dev.txt, (re)built when missing or when
#    requirements-dev.txt changed since it was built;
#  * the system libraries Open3D loads (libusb-1.0-0, libgomp1), installed with apt-get when
#    ldconfig does not know them.
set -euo pipefail
cd "$(dirname "$0")/../.."

PYTHON=${PYTHON:-python3}
VENV=.venv-bench
STAMP=$VENV/requirements-dev.installed

if [ ! -x "$VENV/bin/python" ] || ! cmp -s requirements-dev.txt "$STAMP"; then
    echo "bench_setup: building $VENV from requirements-dev.txt" >&2
    "$PYTHON" -m venv "$VENV"
    "$VENV/bin/pip" install --disable-pip-version-check -q -r requirements-dev.txt
    cp requirements-dev.txt "$STAMP"
fi

missing=()
ldconfig -p | grep -q 'libusb-1\.0\.so\.0' || missing+=(libusb-1.0-0)
ldconfig -p | grep -q 'libgomp\.so\.1' || missing+=(libgomp1)
if [ ${#missing[@]} -gt 0 ]; then
    echo "bench_setup: installing ${missing[*]}" >&2
    SUDO=
    [ "$(id -u)" -eq 0 ] || SUDO=sudo
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
fi
