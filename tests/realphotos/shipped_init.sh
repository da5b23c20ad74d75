#!/usr/bin/env bash
# Rebuilds the start gpmm ships (host/assets/face.init) from its sources: the default model (the
# demo's build), the recipe of docs/real-photos.md on Debian's wallpapers and the example photos of
# the recipe's four repositories, then writes the file and its provenance.
#
#   bash tests/realphotos/shipped_init.sh [--checkouts DIR] [--work DIR] [--seed S] [-o INIT]
#
# --checkouts DIR: where the four repositories are, each as DIR/OWNER+NAME (a work tree or a git
#   directory, also DIR/OWNER+NAME/repo); without it they are cloned (bare) into WORK/checkouts.
# --work DIR: scratch (default /tmp/gpmm-shipped-init): venv-made mapping, sets, pool, logs.
# Takes about 40 minutes on two idle cores (training 35); needs python3 with venv, apt-get
# (`apt-get download` only, nothing is installed) and the shared data ($GPMM_DATA).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
data="${GPMM_DATA:-$(cd "$root/.." && pwd)/shared/data}"
work=/tmp/gpmm-shipped-init; checkouts=""; seed=1; output="$root/host/assets/face.init"
while [ $# -gt 0 ]; do
    case "$1" in
        --checkouts) checkouts="$2"; shift 2 ;;
        --work) work="$2"; shift 2 ;;
        --seed) seed="$2"; shift 2 ;;
        -o|--output) output="$2"; shift 2 ;;
        *) echo "unknown argument $1 (see the comment at the top of $0)" >&2; exit 2 ;;
    esac
done
mkdir -p "$work"
export REALISTIC_DATA="$work/realistic" REALISTIC_VENV="${REALISTIC_VENV:-$work/venv}"
py="$REALISTIC_VENV/bin/python"
(cd "$root" && cargo build --release -p gpmm)
gpmm="$root/target/release/gpmm"

echo "== the default model (the demo's build)"
tdir="$data/template/lee-perry-smith"
[ -f "$work/face.gpmm" ] || "$gpmm" build --template "$tdir/lee-perry-smith.ply" --landmarks "$tdir/landmarks_ibug68.json" \
    --kernel symmetric-full --rank-shape 200 --rank-color 200 --nystrom-points 2000 -o "$work/face.gpmm"

echo "== MediaPipe's 468 -> 68 mapping, the scored sets (left out of the pool), the wallpapers"
GPMM_BIN="$gpmm" bash "$root/tests/realistic/run_all.sh" --mapping-only
mapping="$REALISTIC_DATA/mapping.json"
[ -d "$work/realphotos/test" ] || "$py" "$here/make_set.py" "$work/realphotos" --mapping "$mapping"
[ -f "$work/backgrounds/sources.json" ] || "$py" "$here/backgrounds.py" "$work/backgrounds"

echo "== the pool: photos of people of the recipe's repositories"
repos=$("$py" -c "import sys; sys.path.insert(0, '$here'); import make_pool as m; print(' '.join(r for r, _, _ in m.SOURCES[:m.RECIPE_SOURCES]))")
args=()
for repo in $repos; do
    key="${repo/\//+}"
    if [ -n "$checkouts" ]; then
        path="$checkouts/$key"; [ -d "$path/repo" ] && path="$path/repo"
    else
        path="$work/checkouts/$key.git"
        [ -d "$path" ] || git clone --bare -q "https://github.com/$repo" "$path"
    fi
    args+=(--checkout "$repo=$path")
done
[ -f "$work/pool/sources.json" ] || "$py" "$here/make_pool.py" "$work/pool" --mapping "$mapping" --recipe "${args[@]}" \
    --exclude "$work/realphotos" --exclude "$data/images"

echo "== training (about 30 minutes), then fine-tuning on its own scan mistakes (about 5)"
photos=(--backgrounds "$work/backgrounds" --backgrounds "$work/pool" --photo-faces 0.5 --face-free 0.25 --seed "$seed")
[ -f "$work/people.init" ] || "$gpmm" train-init "$work/face.gpmm" -o "$work/people.init" "${photos[@]}" \
    --preview "$work/scenes.png" | tee "$work/people.json"
"$gpmm" train-init "$work/face.gpmm" --from "$work/people.init" -o "$output" "${photos[@]}" --scan-mistakes \
    | tee "$work/fine-tuned.json"
"$gpmm" detect "$data/images/two_people.jpg" --init "$output" >/dev/null
echo "wrote $output (its provenance: gpmm info $output)"
