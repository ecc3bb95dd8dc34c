#!/bin/sh
# Measure which --transfer default suits which camera: simulate dives rendered linear and with an sRGB curve,
# correct each with --transfer linear and --transfer srgb (method paper), and score them against the true albedo.
# Usage: scripts/transfer-measurement.sh [WORK_DIR] [SEED...]   (needs a release build: cargo build --release)
set -eu
B=${ABYSSLIGHT:-target/release/abysslight}
W=${1:-transfer-measurement}
shift || true
SEEDS=${*:-1 2 3}
for seed in $SEEDS; do
  for enc in linear srgb; do
    D=$W/seed$seed-$enc
    rm -rf "$D"
    "$B" simulate --out "$D/dive" --encode "$enc" --seed "$seed" 2>/dev/null
    for t in linear srgb; do
      "$B" correct -q --water-column "$D/dive/water" --survey "$D/dive/survey" --out "$D/transfer-$t" \
        --contamination 0.2 --transfer "$t"
    done
    echo "## seed $seed, dive rendered $enc"
    "$B" evaluate --truth "$D/dive" --json "$D/evaluation.json" \
      raw="$D/dive/survey" "transfer-linear=$D/transfer-linear" "transfer-srgb=$D/transfer-srgb" 2>/dev/null
  done
done
