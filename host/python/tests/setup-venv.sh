#!/usr/bin/env bash
# Creates (or reuses) a virtual environment of the Python package's tools, idempotently:
#   bash host/python/tests/setup-venv.sh build DIR   maturin, to build the wheel (kept between runs)
#   bash host/python/tests/setup-venv.sh test DIR    the test tools (pytest, h5py, Dask, Pillow, mypy for
#                                                    stubtest) for a venv the wheel is installed into
# Needs CPython >= 3.9 with venv and pip; on Debian, installs python3-venv when missing (as root).
# Then pip installs the tools from PyPI.
set -euo pipefail
kind="${1:?usage: setup-venv.sh build|test DIR}"
venv="${2:?usage: setup-venv.sh build|test DIR}"
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
case "$kind" in
    build) "$venv/bin/python" -m pip install --quiet --upgrade pip "maturin>=1.9,<2" ;;
    test) "$venv/bin/python" -m pip install --quiet pytest h5py "dask[distributed]" mypy pillow ;;
    *) log "unknown kind '$kind' (build or test)"; exit 1 ;;
esac
