#!/usr/bin/env bash
# Instructions per function of a firmware run under QEMU (the breakdown in docs/evaluation.md,
# "Instructions and memory"): runs the firmware once through run.sh (which builds it and checks
# the run ends with status=ok), then again with QEMU's translation and execution log piped to
# gpmm-qemu-profile, which multiplies each block's instructions by its executions and sums them
# per symbol of the ELF.
#
#   firmware-sim/profile.sh --data PARTITION [--profile m4f|m7] [--top N] [--json] [--timeout SECONDS]
#
# PARTITION: a data partition as `gpmm device-fit … --keep-partition FILE` writes it.
# stdout: the total, then the top N functions (default 30) by instructions and share; with --json
# one object {"format":"gpmm-qemu-profile","version":1,"instructions":…,"functions":[…]}.
# stderr: progress. The log runs to hundreds of millions of lines: a default fit takes a minute or
# two (QEMU writes the log; the counter keeps up).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
profile=m4f
data=""
top=30
json=()
timeout_s=1800
log() { echo "profile.sh: $*" >&2; }
die() { log "$*"; exit 1; }

while [ $# -gt 0 ]; do
    case "$1" in
        --data) data="${2:?--data needs a file}"; shift 2 ;;
        --profile) profile="${2:?--profile needs m4f or m7}"; shift 2 ;;
        --top) top="${2:?--top needs a number}"; shift 2 ;;
        --json) json=(--json); shift ;;
        --timeout) timeout_s="${2:?--timeout needs seconds}"; shift 2 ;;
        -h|--help) sed -n '2,14p' "${BASH_SOURCE[0]}"; exit 0 ;;
        *) die "unknown argument $1 (see --help)" ;;
    esac
done
[ -n "$data" ] || die "--data PARTITION is required (gpmm device-fit … --keep-partition FILE writes one)"
[ -f "$data" ] || die "no such data file: $data"
case "$profile" in
    m4f) machine=(-M mps2-an386 -cpu cortex-m4) ;;
    m7) machine=(-M mps2-an500 -cpu cortex-m7) ;;
    *) die "unknown profile $profile (m4f or m7)" ;;
esac

# 1. Build and run once the ordinary way: the ELF, and a run known to end well.
log "building and running the $profile firmware (run.sh)"
"$here/run.sh" --profile "$profile" --data "$data" --timeout "$timeout_s" >/dev/null
elf="$here/target/thumbv7em-none-eabihf/release/gpmm-firmware-sim"
[ -f "$elf" ] || die "no ELF at $elf"

# 2. The counter (a host program; from / so that firmware-sim's thumbv7em target does not apply).
counter="$here/target/host/release/gpmm-qemu-profile"
if [ ! -x "$counter" ] || [ "$here/profile/src/main.rs" -nt "$counter" ] || [ "$here/profile/Cargo.toml" -nt "$counter" ]; then
    log "building the profile counter"
    (cd / && cargo build --release --locked -q --manifest-path "$here/profile/Cargo.toml" --target-dir "$here/target/host" >&2)
fi

# 3. The run again with QEMU's log going through a FIFO to the counter.
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkfifo "$tmp/log"
part_start=$(( 0x$(arm-none-eabi-nm "$elf" | awk '$3 == "_gpmm_data_start" { print $1 }') ))
"$counter" "$elf" --top "$top" "${json[@]}" <"$tmp/log" >"$tmp/out" &
counter_pid=$!
log "profiling (QEMU -d in_asm,exec,nochain)"
set +e
timeout "$timeout_s" qemu-system-arm "${machine[@]}" -display none -monitor none -serial null \
    -semihosting-config enable=on,target=native -icount shift=0 -kernel "$elf" \
    -device "loader,file=$data,addr=$(printf '0x%08x' "$part_start")" \
    -d in_asm,exec,nochain -D "$tmp/log" </dev/null >/dev/null
qemu_rc=$?
wait "$counter_pid"
counter_rc=$?
set -e
[ "$qemu_rc" -eq 0 ] || die "QEMU exited with status $qemu_rc"
[ "$counter_rc" -eq 0 ] || die "the counter failed (status $counter_rc)"
cat "$tmp/out"
