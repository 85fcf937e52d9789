#!/usr/bin/env bash
# Time `pipewave calibrate` of two revisions of pipewave, each built from its own commit,
# alternated on one machine (docs/performance.md, "Against an earlier version").
#
# Usage: scripts/compare-builds.sh [-n SEGMENTS] [-s SEED] [-r ROUNDS] [--keep] OLD_REV [NEW_REV]
#                                   [-- SYNTH_OPTION...]
#
# Each revision is checked out in its own temporary `git worktree` and built in release with its
# own CARGO_TARGET_DIR; the checkout you run this from is not touched. The two target
# directories, old/ and new/ under $COMPARE_BUILDS_CACHE (default
# ~/.cache/pipewave-compare-builds), are kept between runs so that the next run compiles only
# pipewave itself, not its dependencies again; delete that directory to reclaim the space.
#
# One synthetic network is written by the NEW binary (`synth --segments N --seed S`, plus any
# SYNTH_OPTION given after `--`). Each binary imports it into its own database with its own
# `import` (the schema may differ between versions). Then, for R rounds, each binary calibrates
# a fresh copy of its database on one thread,
#     RAYON_NUM_THREADS=1 pipewave calibrate --db COPY --jobs 1
# the order swapping every round (old first in odd rounds, new first in even ones), and the
# user CPU time of each run is taken by `/usr/bin/time -f %U`. Printed: each binary's seconds
# per round, the medians, their ratio old/new, and each binary's calibrate summary line with
# its fit count. A fresh copy each round makes every round refit every segment.
#
# What is timed is the whole `calibrate`: the fits, their database writes and whatever else the
# version does after them (from fit algorithm 20 on, the soil-field update: its line is printed).
set -euo pipefail

usage() {
    sed -n '4,6p' "$0" | sed 's/^# \{0,1\}//'
    cat <<'EOF'

  -n, --segments N   synthetic segments (default 1000)
  -s, --seed S       seed of the synthetic network (default 20261128)
  -r, --rounds R     calibrate runs of each binary, alternated (default 3)
      --keep         keep the work directory (network, databases, logs) and say where it is
  OLD_REV, NEW_REV   any commit names git understands; NEW_REV defaults to HEAD (committed
                     changes only: uncommitted edits are not built)

Without options (1000 segments, 3 rounds) the timing against pipewave 0.1 takes about 4-5
minutes, plus 1-3 minutes to rebuild pipewave twice (7.4 minutes in all on a busy 2-core
machine; 0.1's calibrate takes about 4x the CPU of fit algorithm 20's).
EOF
}

die() {
    echo "compare-builds: $*" >&2
    exit 2
}

segments=1000
seed=20261128
rounds=3
keep=0
revs=()
synth_extra=()
while (($#)); do
    case "$1" in
    -n | --segments)
        (($# >= 2)) || die "$1 needs a value"
        segments=$2
        shift 2
        ;;
    -s | --seed)
        (($# >= 2)) || die "$1 needs a value"
        seed=$2
        shift 2
        ;;
    -r | --rounds)
        (($# >= 2)) || die "$1 needs a value"
        rounds=$2
        shift 2
        ;;
    --keep)
        keep=1
        shift
        ;;
    -h | --help)
        usage
        exit 0
        ;;
    --)
        shift
        synth_extra=("$@")
        break
        ;;
    -*) die "unknown option $1 (see --help)" ;;
    *)
        revs+=("$1")
        shift
        ;;
    esac
done
((${#revs[@]} >= 1 && ${#revs[@]} <= 2)) || {
    usage >&2
    exit 2
}
[[ $segments =~ ^[1-9][0-9]*$ ]] || die "--segments must be a positive whole number, not '$segments'"
[[ $seed =~ ^[0-9]+$ ]] || die "--seed must be a whole number, not '$seed'"
[[ $rounds =~ ^[1-9][0-9]*$ ]] || die "--rounds must be a positive whole number, not '$rounds'"
[[ -x /usr/bin/time ]] || die "/usr/bin/time is needed (Debian/Ubuntu: apt-get install time)"

repo=$(git rev-parse --show-toplevel 2>/dev/null) || die "run this inside the pipewave repository"
resolve() {
    git -C "$repo" rev-parse --verify --quiet "$1^{commit}" || die "'$1' names no commit"
}
old_sha=$(resolve "${revs[0]}")
new_sha=$(resolve "${revs[1]:-HEAD}")

cache=${COMPARE_BUILDS_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/pipewave-compare-builds}
mkdir -p "$cache"
work=$(mktemp -d "${TMPDIR:-/tmp}/pipewave-compare.XXXXXX")
worktrees=()
cleanup() {
    local wt
    for wt in "${worktrees[@]}"; do
        git -C "$repo" worktree remove --force "$wt" 2>/dev/null || true
    done
    git -C "$repo" worktree prune 2>/dev/null || true
    if ((keep)); then
        echo "work directory kept: $work"
    else
        rm -rf "$work"
    fi
}
trap cleanup EXIT

# build SHA ROLE: check SHA out in a temporary worktree, build it in release in the target
# directory of its role (old or new), copy the binary to $work/pipewave-SHA and remove the
# worktree.
build() {
    local sha=$1 wt="$work/src-${1:0:12}" target="$cache/$2"
    if [[ -x "$work/pipewave-$sha" ]]; then
        return
    fi
    git -C "$repo" worktree add --detach --quiet "$wt" "$sha"
    worktrees+=("$wt")
    echo "building $(git -C "$repo" log -1 --format='%h (%ad) %s' --date=short "$sha")" >&2
    (cd "$wt" && CARGO_TARGET_DIR="$target" cargo build --release --locked --bin pipewave) \
        >"$work/build-${sha:0:12}.log" 2>&1 || {
        tail -n 30 "$work/build-${sha:0:12}.log" >&2
        die "revision ${sha:0:12} does not build (log above)"
    }
    cp "$target/release/pipewave" "$work/pipewave-$sha"
    git -C "$repo" worktree remove --force "$wt"
}
build "$old_sha" old
build "$new_sha" new
old_bin="$work/pipewave-$old_sha"
new_bin="$work/pipewave-$new_sha"

echo "synth: $segments segments, seed $seed${synth_extra[*]:+, ${synth_extra[*]}} (new binary)" >&2
"$new_bin" synth --out "$work/net" --segments "$segments" --seed "$seed" "${synth_extra[@]}" \
    >"$work/synth.log" 2>&1 || {
    cat "$work/synth.log" >&2
    die "synth failed"
}

# import NAME BINARY: the network into $work/NAME.sqlite with that binary's own import.
import() {
    "$2" import --db "$work/$1.sqlite" --segments "$work/net/segments.csv" \
        --measurements "$work/net/measurements.csv" >"$work/import-$1.log" 2>&1 || {
        cat "$work/import-$1.log" >&2
        die "the $1 binary cannot import the network (log above)"
    }
}
import old "$old_bin"
import new "$new_bin"

# calibrate NAME BINARY ROUND: calibrate a fresh copy of NAME's database on one thread; append
# the user CPU seconds to $work/NAME.cpu and keep the output in $work/NAME-ROUND.log.
calibrate() {
    local db="$work/$1-round.sqlite" ext
    rm -f "$db" "$db-wal" "$db-shm"
    for ext in "" -wal -shm; do
        if [[ -e "$work/$1.sqlite$ext" ]]; then cp "$work/$1.sqlite$ext" "$db$ext"; fi
    done
    RAYON_NUM_THREADS=1 /usr/bin/time -f %U -o "$work/$1.time" \
        "$2" calibrate --db "$db" --jobs 1 >"$work/$1-$3.log" 2>&1 || {
        tail -n 20 "$work/$1-$3.log" >&2
        die "calibrate with the $1 binary failed in round $3 (log above)"
    }
    tail -n 1 "$work/$1.time" >>"$work/$1.cpu"
    printf '  %s %8.2f s' "$1" "$(tail -n 1 "$work/$1.time")"
}

echo "old: $(git -C "$repo" log -1 --format='%h (%ad) %s' --date=short "$old_sha")"
echo "new: $(git -C "$repo" log -1 --format='%h (%ad) %s' --date=short "$new_sha")"
echo "network: $(tail -n 1 "$work/synth.log")"
echo "user CPU of RAYON_NUM_THREADS=1 pipewave calibrate --jobs 1, fresh database each round:"
: >"$work/old.cpu"
: >"$work/new.cpu"
for ((r = 1; r <= rounds; r++)); do
    printf 'round %d:' "$r"
    if ((r % 2)); then
        calibrate old "$old_bin" "$r"
        calibrate new "$new_bin" "$r"
    else
        calibrate new "$new_bin" "$r"
        calibrate old "$old_bin" "$r"
    fi
    echo
done

median() { sort -g "$1" | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }
old_median=$(median "$work/old.cpu")
new_median=$(median "$work/new.cpu")
awk -v o="$old_median" -v n="$new_median" 'BEGIN {
    printf "median: old %.2f s, new %.2f s; old/new %.2fx\n", o, n, (n > 0) ? o / n : 0 }'

# summary NAME: the calibrate summary line of each round must agree on the number fitted.
summary() {
    local line counts
    line=$(grep -m 1 '^calibrate: [0-9]* fitted' "$work/$1-1.log" || echo "(no summary line)")
    counts=$(cat "$work/$1"-*.log | sed -n 's/^calibrate: \([0-9]*\) fitted.*/\1/p' | sort -u | tr '\n' ' ')
    echo "$1: $line"
    grep -m 1 '^field: ' "$work/$1-1.log" | sed "s/^/$1: /" || true
    if [[ $(wc -w <<<"$counts") -ne 1 ]]; then
        echo "$1: warning: the rounds fitted different numbers of segments: $counts"
    fi
    local n=${counts%% *}
    if [[ -n $n && $n -gt 0 ]]; then
        awk -v s="$(median "$work/$1.cpu")" -v n="$n" -v name="$1" \
            'BEGIN { printf "%s: %.1f ms of CPU per fitted segment (median round)\n", name, 1e3 * s / n }'
    fi
}
summary old
summary new
