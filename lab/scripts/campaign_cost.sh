#!/bin/sh
# What the change test adds to a calibrate (issue 63): one synthetic network of N segments, every
# pipe measured in two campaigns, calibrated (a) with only its latest campaign imported and (b)
# with both, alternated ROUNDS times in one run. Prints each time and the ratio b/a.
# Usage: lab/scripts/campaign_cost.sh [N] [ROUNDS]   (from the repository root, after
# `cargo build --release`)
set -eu
N=${1:-1000}
ROUNDS=${2:-2}
PW=${PW:-target/release/pipewave}
DIR=$(mktemp -d)
"$PW" synth --out "$DIR/net" --segments "$N" --seed 63063 --no-real-cases --campaigns 2 --changed-fraction 0.3 >/dev/null
# The latest campaign alone.
awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "campaign") c = i; print; next } $c != "FD-2026"' \
    "$DIR/net/measurements.csv" > "$DIR/latest.csv"
for kind in one two; do
    m="$DIR/net/measurements.csv"
    [ "$kind" = one ] && m="$DIR/latest.csv"
    "$PW" import --db "$DIR/$kind.sqlite" --segments "$DIR/net/segments.csv" --measurements "$m" >/dev/null
done
total_one=0; total_two=0
r=1
while [ "$r" -le "$ROUNDS" ]; do
    for kind in one two; do
        s=$(date +%s.%N)
        "$PW" calibrate --db "$DIR/$kind.sqlite" --force >/dev/null
        e=$(date +%s.%N)
        t=$(echo "$e - $s" | bc)
        echo "round $r, $kind campaign(s): $t s"
        if [ "$kind" = one ]; then total_one=$(echo "$total_one + $t" | bc); else total_two=$(echo "$total_two + $t" | bc); fi
    done
    r=$((r + 1))
done
echo "ratio two/one: $(echo "scale=3; $total_two / $total_one" | bc)"
rm -rf "$DIR"
