#!/usr/bin/env bash
# Regenerates every number and plot of docs/RESULTS.md (multi-process runs, seed 1).
# Usage: scripts/results.sh [OUT]   (default OUT=results/report; plots are copied to docs/results/)
# Takes about 10 minutes on a 2-core machine. Needs python3 for the tables.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-results/report}
mkdir -p "$out" docs/results
cargo build --release --bins
sup=target/release/supervisor
run() { local name=$1; shift; echo "== $name: supervisor $*" >&2; "$sup" --quiet --overwrite --out "$out/$name" "$@" >/dev/null; }

# Thesis figures (4 trials, 50 000 episodes each, multi-process).
"$sup" reproduce fig10 --overwrite --out "$out/fig10" | tee "$out/fig10.txt"
"$sup" reproduce fig11 --overwrite --out "$out/fig11" | tee "$out/fig11.txt"

# Communication modes on s3, with periodic greedy evaluation.
for comm in none flags compact; do
  run "s3-$comm" --scenario s3 --uavs 2 --comm "$comm" --episodes 50000 --eval-every 2500
done
"$sup" plot --out "$out/s3-comm.svg" --title "s3: UAV1 learning with each communication mode" \
  --curve "$out/s3-none/curve.csv=none" --curve "$out/s3-flags/curve.csv=flags" \
  --curve "$out/s3-compact/curve.csv=compact"

# Communication modes with 8 UAVs on the default generated map.
for comm in none flags compact; do
  run "n8-$comm" --uavs 8 --comm "$comm" --episodes 5000 --eval-every 500
done
"$sup" plot --out "$out/n8-comm.svg" --title "8 UAVs (generated map): UAV1 learning with each communication mode" \
  --curve "$out/n8-none/curve.csv=none" --curve "$out/n8-flags/curve.csv=flags" \
  --curve "$out/n8-compact/curve.csv=compact"

# The issue's scale runs, and the scaling table (compact mode beyond 2 UAVs).
run n8-20000 --uavs 8 --episodes 20000
run n32-5000 --uavs 32 --episodes 5000
for n in 1 2 4 8 16 32; do
  run "scale-$n" --uavs "$n" --episodes 2000
done

cp "$out/fig10/fig10.svg" "$out/fig11/fig11.svg" "$out/s3-comm.svg" "$out/n8-comm.svg" docs/results/
python3 scripts/tables.py "$out" | tee "$out/tables.md"
