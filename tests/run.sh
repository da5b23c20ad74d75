#!/usr/bin/env bash
# The whole gpmm test suite, from a fresh checkout on a fresh Debian machine.
# Installs what it needs, then: formatting, lints, unit + integration tests of the workspace, and
# the Python package built into a virtual environment with its pytest suite.
# Usage: bash tests/run.sh            (GPMM_DATA overrides the data directory, default ../shared/data)
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

step "toolchain"
if ! command -v cargo >/dev/null 2>&1; then
    echo "cargo not found: install Rust (rustup) first" >&2
    exit 1
fi
cargo --version
rustup component list --installed 2>/dev/null | grep -q rustfmt || rustup component add rustfmt clippy 2>/dev/null || true

export GPMM_DATA="${GPMM_DATA:-$(cd .. && pwd)/shared/data}"
# In CI the data must be there: tests that need it fail instead of skipping.
if [ -n "${CI:-}" ]; then export GPMM_REQUIRE_DATA=1; fi
if [ ! -d "$GPMM_DATA" ]; then
    echo "warning: data directory $GPMM_DATA is missing; tests that need the template will say so" >&2
fi

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy -D warnings"
cargo clippy --workspace --all-targets -- -D warnings

step "firmware toolchain (Debian packages, QEMU)"
# qemu-system-arm, binutils-arm-none-eabi, a thumbv7em toolchain and the defmt decoder, when
# missing (tests/tests/firmware_render.rs runs the firmware under QEMU and fails without them).
bash firmware-sim/install-deps.sh

step "cargo test (workspace)"
cargo test --workspace 2>&1 | tee target/test-output.txt

step "Python package (the abi3 wheel, installed into a fresh venv; pytest and stubtest against it)"
bash host/python/tests/setup-venv.sh build target/py-venv
# The package's tests compare against the gpmm program. Both the program and the native module
# are built in the dev profile that `cargo test` has just compiled the dependencies for (they are
# at opt-level 3 there too): a release build would compile every dependency a second time
# (minutes on two cores). Users' wheels build in release (pyproject.toml).
cargo build -p gpmm
rm -f target/wheels/gpmm_faces-*.whl
target/py-venv/bin/maturin build --profile dev -m host/python/Cargo.toml --out target/wheels
wheel=$(ls target/wheels/gpmm_faces-*.whl)
rm -rf target/py-wheel-venv
python3 -m venv target/py-wheel-venv
t0=$(date +%s%N)
target/py-wheel-venv/bin/pip install --quiet "$wheel"
echo "the wheel installed into a fresh venv in $(( ($(date +%s%N) - t0) / 1000000 )) ms"
bash host/python/tests/setup-venv.sh test target/py-wheel-venv
# From an empty directory, so that `import gpmm` can only find the installed wheel.
(cd target/py-wheel-venv && bin/python -c 'import gpmm, sys; assert "site-packages" in gpmm.__file__, gpmm.__file__')
(cd target/py-wheel-venv && bin/python -m mypy.stubtest gpmm)
GPMM_BIN="$PWD/target/debug/gpmm" target/py-wheel-venv/bin/python -m pytest host/python/tests -q -p no:cacheprovider 2>&1 \
    | tee target/pytest-output.txt

# Print one closing summary line over all test binaries and the pytest suite.
passed=$(grep -Eo '^test result: [a-zA-Z]+\. [0-9]+ passed' target/test-output.txt | awk '{s+=$4} END {print s+0}')
failed=$(grep -Eo '[0-9]+ failed' target/test-output.txt | awk '{s+=$1} END {print s+0}')
# pytest's last line: "23 passed in 12.5s" or "1 failed, 22 passed in …" (awk, not grep: no match is 0).
py_passed=$(tail -n 1 target/pytest-output.txt | awk '{for (i = 2; i <= NF; i++) if ($i ~ /^passed/) s += $(i-1)} END {print s+0}')
py_failed=$(tail -n 1 target/pytest-output.txt | awk '{for (i = 2; i <= NF; i++) if ($i ~ /^failed/) s += $(i-1)} END {print s+0}')
echo "$((passed + py_passed)) passed, $((failed + py_failed)) failed"
