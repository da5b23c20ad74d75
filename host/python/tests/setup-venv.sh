#!/usr/bin/env bash
# Creates (or reuses) the virtual environment the Python package is tested in, idempotently:
#   bash host/python/tests/setup-venv.sh DIR
# Needs CPython >= 3.9 with venv and pip; on Debian, installs python3-venv when missing (as root).
# Then pip installs the build and test dependencies from PyPI.
set -euo pipefail
venv="${1:?usage: setup-venv.sh DIR}"
log() { echo "setup-venv: $*" >&2; }

if ! python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then
    if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
        log "apt-get install python3-venv"
        DEBIAN_FRONTEND=noninteractive apt-get update -qq >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends python3-venv python3-pip >&2
    else
        log "python3 lacks venv/ensurepip: install python3-venv"
        exit 1
    fi
fi
if [ ! -x "$venv/bin/python" ]; then
    log "python3 -m venv $venv ($(python3 --version))"
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet "maturin>=1.9,<2" numpy h5py pytest "dask[distributed]"
