#!/usr/bin/env bash
# Builds the firmware, runs it under QEMU and decodes its defmt log.
#
#   firmware-sim/run.sh [--profile m4f|m7] [--map mps2|netduinoplus2] [--data FILE] [--timeout SECONDS]
#   firmware-sim/run.sh --elf ELF [--data FILE] ...     (run a built ELF; cargo's runner)
#
# stdout: the decoded log lines, then one machine-readable line
#   GPMM_FIGURES {"instructions":…,"stack_peak_bytes":…,"checksum":…,"flash_bytes":…,
#                 "ram_static_bytes":…,…}
# stderr: progress, build output, sizes.
# Exit status: 0 if the firmware reported status=ok and exited through semihosting with
# 0; non-zero otherwise (build failure, firmware failure, timeout, undecodable log).
#
# Environment: GPMM_FW_TOOLCHAIN=auto|rustup|debian (see install-deps.sh).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
target=thumbv7em-none-eabihf
profile=m4f
map=mps2
data=""
elf=""
timeout_s=300
log() { echo "run.sh: $*" >&2; }
die() { log "$*"; exit 1; }

while [ $# -gt 0 ]; do
    case "$1" in
        --profile) profile="${2:?--profile needs m4f or m7}"; shift 2 ;;
        --map) map="${2:?--map needs mps2 or netduinoplus2}"; shift 2 ;;
        --data) data="${2:?--data needs a file}"; shift 2 ;;
        --elf) elf="${2:?--elf needs a file}"; shift 2 ;;
        --timeout) timeout_s="${2:?--timeout needs seconds}"; shift 2 ;;
        -h|--help) sed -n '2,15p' "${BASH_SOURCE[0]}"; exit 0 ;;
        *) die "unknown argument $1 (see --help)" ;;
    esac
done
case "$profile" in m4f|m7) ;; *) die "unknown profile $profile (m4f or m7)" ;; esac
case "$map" in
    mps2) ;;
    netduinoplus2) [ "$profile" = m4f ] || die "the netduinoplus2 memory map (an STM32F405) takes the m4f profile" ;;
    stm32f405|nrf52840) die "the $map map is for a board: build and flash it with probe-rs (firmware-sim/README.md, \"On a board\")" ;;
    *) die "unknown memory map $map (mps2 or netduinoplus2)" ;;
esac
if [ -n "$data" ]; then
    [ -f "$data" ] || die "no such data file: $data"
    data="$(cd "$(dirname "$data")" && pwd)/$(basename "$data")"
fi

# 1. Tools (idempotent; fast when everything is there). Last line: toolchain=…
toolchain="$("$here/install-deps.sh" | tail -n 1)"
toolchain="${toolchain#toolchain=}"
decoder="$here/target/host/release/gpmm-defmt-decode"

# 2. Build (unless an ELF was given).
if [ -z "$elf" ]; then
    features=()
    [ "$profile" = m7 ] && features=(--features m7)
    # Another map builds in its own target directory: switching features in one would rebuild
    # the firmware each time, and runs of both at once would race for the one ELF.
    target_dir="$here/target"
    [ "$map" = netduinoplus2 ] && { features=(--features netduinoplus2); target_dir="$here/target/map-netduinoplus2"; }
    cd "$here"
    # Outer settings that would change what or where cargo builds (e.g. when a test
    # under cargo calls this script) do not apply to the firmware.
    unset RUSTFLAGS CARGO_ENCODED_RUSTFLAGS CARGO_BUILD_RUSTFLAGS CARGO_BUILD_TARGET CARGO_TARGET_DIR CARGO_BUILD_TARGET_DIR
    args=(build --release --locked --target "$target" --target-dir "$target_dir" "${features[@]}")
    log "building ($toolchain toolchain, profile $profile)"
    if [ "$toolchain" = debian ]; then
        RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 /usr/bin/cargo "${args[@]}" -Z build-std=core
    else
        env -u RUSTC -u RUSTC_BOOTSTRAP cargo "${args[@]}"
    fi
    elf="$target_dir/$target/release/gpmm-firmware-sim"
fi
[ -f "$elf" ] || die "no ELF at $elf"

# 3. The memory map the ELF was linked with (symbols from memory-*.x).
sym() { arm-none-eabi-nm "$elf" | awk -v s="$2" '$3 == s { print $1 }' | head -n 1 | sed 's/^/0x/'; }
ram_size=$(( $(sym "$elf" _gpmm_ram_size) ))
flash_size=$(( $(sym "$elf" _gpmm_flash_size) ))
part_start=$(( $(sym "$elf" _gpmm_data_start) ))
part_end=$(( $(sym "$elf" _gpmm_data_end) ))
part_bytes=$(( part_end - part_start ))
code_budget=$(( flash_size - part_bytes ))
statics_size=$(( $(sym "$elf" _gpmm_statics_size) ))
stack_size=$(( $(sym "$elf" _gpmm_stack_size) ))
case "$(( $(sym "$elf" _gpmm_memory_map) )):$ram_size" in
    1:196608) elf_profile=m4f; machine=(-M mps2-an386 -cpu cortex-m4) ;;
    1:524288) elf_profile=m7; machine=(-M mps2-an500 -cpu cortex-m7) ;;
    3:196608) elf_profile=m4f; machine=(-M netduinoplus2) ;;
    2:*|4:*) die "the ELF is linked for a board (STM32F405 or nRF52840), not a QEMU machine: flash it with probe-rs, or run --map netduinoplus2" ;;
    *) die "ELF has an unknown memory map (RAM $ram_size bytes)" ;;
esac
part_hex=$(printf '0x%08x' "$part_start")

# 4. Sizes: flash = text + data (initial values of .data live in flash), static RAM = data + bss.
read -r text dat bss _ < <(arm-none-eabi-size -B "$elf" | tail -n 1)
flash_bytes=$(( text + dat ))
ram_static_bytes=$(( dat + bss ))
arm-none-eabi-size -B "$elf" >&2
log "profile $elf_profile: flash $flash_bytes of $code_budget bytes for code (+ $part_bytes bytes data partition at $part_hex, $flash_size in all); static RAM $ram_static_bytes of $ram_size bytes"

# 5. Run under QEMU. -icount shift=0: 1 instruction = 1 ns of virtual time, so SysTick
# (25 MHz) counts instructions / 40. Semihosting output (the raw defmt stream) goes to
# QEMU's stdout; nothing else writes there (no display, monitor or serial).
loader=()
if [ -n "$data" ]; then
    data_bytes=$(stat -c %s "$data")
    [ "$data_bytes" -le "$part_bytes" ] || die "$data is $data_bytes bytes; the $elf_profile data partition holds $part_bytes"
    loader=(-device "loader,file=$data,addr=$part_hex")
    log "data partition: $data ($data_bytes bytes) at $part_hex"
fi
# Per-run files (several runs may go on at once, e.g. parallel tests); copied to
# target/defmt-$elf_profile.{raw,log} at the end for inspection (the last run wins).
mkdir -p "$here/target"
raw="$(mktemp "$here/target/defmt-$elf_profile.XXXXXX.raw")"
declog="${raw%.raw}.log"
trap 'rm -f "$raw" "$declog"' EXIT
qemu=(qemu-system-arm "${machine[@]}" -display none -monitor none -serial null
      -semihosting-config enable=on,target=native -icount shift=0 -kernel "$elf" "${loader[@]}")
log "${qemu[*]}"
set +e
timeout "$timeout_s" "${qemu[@]}" </dev/null >"$raw"
qemu_rc=$?
set -e

# 6. Decode.
set +e
"$decoder" "$elf" --figures flash_bytes="$flash_bytes" ram_static_bytes="$ram_static_bytes" \
    flash_code_budget_bytes="$code_budget" ram_budget_bytes="$ram_size" statics_budget_bytes="$statics_size" \
    stack_budget_bytes="$stack_size" qemu_machine="${machine[1]}" qemu_exit="$qemu_rc" <"$raw" \
    | tee "$declog"
decode_rc=${PIPESTATUS[0]}
set -e
cp "$raw" "$here/target/defmt-$elf_profile.raw.tmp$$" && mv -f "$here/target/defmt-$elf_profile.raw.tmp$$" "$here/target/defmt-$elf_profile.raw"
cp "$declog" "$here/target/defmt-$elf_profile.log.tmp$$" && mv -f "$here/target/defmt-$elf_profile.log.tmp$$" "$here/target/defmt-$elf_profile.log"

if [ "$qemu_rc" -eq 124 ]; then
    die "QEMU timed out after ${timeout_s}s (the firmware did not exit)"
elif [ "$qemu_rc" -ne 0 ]; then
    die "the firmware failed (QEMU exit status $qemu_rc)"
elif [ "$decode_rc" -ne 0 ]; then
    die "the defmt log did not decode (status $decode_rc)"
elif ! grep -q '^INFO  status=ok$' "$declog"; then
    die "the firmware exited without status=ok"
fi
log "ok"
