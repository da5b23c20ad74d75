#!/usr/bin/env bash
# Installs what the firmware simulator needs, idempotently (Debian 12; run as root).
#
#   qemu-system-arm          runs the firmware (machine mps2-an386, Cortex-M4F)
#   binutils-arm-none-eabi   arm-none-eabi-ld (linker) and arm-none-eabi-size (budgets)
#   a Rust toolchain for thumbv7em-none-eabihf, one of:
#     rustup  `rustup target add thumbv7em-none-eabihf` (needs rustup's server), or
#     debian  rustc-web cargo-web rust-web-src: /usr/bin/cargo with RUSTC=/usr/bin/rustc,
#             RUSTC_BOOTSTRAP=1 and -Z build-std=core (works offline from Debian's mirror)
#   the defmt decoder: firmware-sim/decode (a small host program on the defmt-decoder
#     crate), built from crates.io into firmware-sim/target/host.
#
# GPMM_FW_TOOLCHAIN=auto|rustup|debian (default auto: rustup when it can provide the
# target, else Debian's packages). Prints the chosen toolchain as its last line
# (`toolchain=rustup` or `toolchain=debian`), which run.sh reads.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
want="${GPMM_FW_TOOLCHAIN:-auto}"
target=thumbv7em-none-eabihf
log() { echo "install-deps: $*" >&2; }

apt_updated=0
apt_install() {
    # Installs the Debian packages given that are not installed yet; `apt-get update` at most once.
    local missing=()
    for p in "$@"; do
        if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed'; then
            missing+=("$p")
        fi
    done
    [ "${#missing[@]}" -eq 0 ] && return 0
    if [ "$(id -u)" -ne 0 ]; then
        log "missing Debian packages ${missing[*]}; run this script as root"
        exit 1
    fi
    if [ "$apt_updated" -eq 0 ]; then
        log "apt-get update"
        DEBIAN_FRONTEND=noninteractive apt-get update -qq >&2
        apt_updated=1
    fi
    log "apt-get install ${missing[*]}"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
}

# 1. QEMU and binutils: always from Debian.
if ! command -v qemu-system-arm >/dev/null || ! command -v arm-none-eabi-ld >/dev/null \
    || ! command -v arm-none-eabi-size >/dev/null; then
    apt_install qemu-system-arm binutils-arm-none-eabi
fi

# 2. The Rust target.
rustup_has_target() {
    command -v rustup >/dev/null && rustup target list --installed 2>/dev/null | grep -qx "$target"
}
debian_ready() {
    [ -x /usr/bin/rustc ] && [ -x /usr/bin/cargo ] \
        && [ -d "$(/usr/bin/rustc --print sysroot)/lib/rustlib/src/rust/library/core" ]
}
toolchain=""
if [ "$want" = auto ] || [ "$want" = rustup ]; then
    if rustup_has_target; then
        toolchain=rustup
    elif command -v rustup >/dev/null; then
        log "rustup target add $target"
        if timeout 60 rustup target add "$target" >&2; then
            toolchain=rustup
        else
            log "rustup could not add $target"
        fi
    fi
    if [ -z "$toolchain" ] && [ "$want" = rustup ]; then
        log "GPMM_FW_TOOLCHAIN=rustup but rustup cannot provide $target"
        exit 1
    fi
fi
if [ -z "$toolchain" ]; then
    if ! debian_ready; then
        apt_install rustc-web cargo-web rust-web-src
    fi
    debian_ready || { log "Debian's Rust toolchain is incomplete"; exit 1; }
    toolchain=debian
fi

# 3. The defmt decoder (host program). Built with whatever host cargo there is.
decoder="$here/target/host/release/gpmm-defmt-decode"
if [ ! -x "$decoder" ] || [ "$here/decode/src/main.rs" -nt "$decoder" ] \
    || [ "$here/decode/Cargo.toml" -nt "$decoder" ]; then
    if command -v cargo >/dev/null && cargo --version >/dev/null 2>&1; then
        host_cargo=(cargo)
    else
        host_cargo=(/usr/bin/cargo)
        export RUSTC=/usr/bin/rustc
    fi
    log "building the defmt decoder ($("${host_cargo[@]}" --version))"
    # From / so that no .cargo/config.toml (firmware-sim's sets a thumbv7em target) applies.
    (cd / && "${host_cargo[@]}" build --release --locked -q \
        --manifest-path "$here/decode/Cargo.toml" --target-dir "$here/target/host" >&2)
fi

echo "toolchain=$toolchain"
