#!/usr/bin/env bash
# The LoCM ablation of locm_table.sh for one set of base weights: none and full once,
# lora at LoRA seeds 0, 1, 2, then the 3-seed mean of lora's EPE per scene.
# Usage: WEIGHTS=FILE NAME=TAG evflow/benches/locm_seeds.sh [WORKDIR]
#   (WEIGHTS defaults to the shipped weights; NAME tags the output directories, so
#   different weights never reuse each other's runs. SCENES as in locm_table.sh.)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
work="${1:-$here/../../target/locm-table}"
name="${NAME:-default}"
mkdir -p "$work/cfg"
[ -n "${WEIGHTS:-}" ] && export EVFLOW_WEIGHTS="$WEIGHTS"
for s in 0 1 2; do echo "seed = $s" >"$work/cfg/seed$s.toml"; done
rows="$(mktemp)"
MODES="none full" TAG="-$name" EVFLOW_CONFIG="$work/cfg/seed0.toml" "$here/locm_table.sh" "$work" | tee "$rows"
for s in 0 1 2; do
  MODES=lora TAG="-$name-s$s" EVFLOW_CONFIG="$work/cfg/seed$s.toml" "$here/locm_table.sh" "$work" | tail -n +3 | tee -a "$rows"
done
echo
echo "3-seed lora mean vs none (EPE px), weights ${WEIGHTS:-shipped}:"
awk -F'|' '{gsub(/ /, "", $2); gsub(/ /, "", $4); gsub(/ /, "", $6)}
  $4 ~ /^none/ {none[$2] = $6}
  $4 ~ /^lora/ {s[$2] += $6; n[$2]++; l[$2] = l[$2] " " $6}
  END {for (k in s) printf "%s: none %.3f, lora %.3f (seeds:%s), lora − none %+.3f\n",
       k, none[k], s[k] / n[k], l[k], s[k] / n[k] - none[k]}' "$rows"
rm -f "$rows"
