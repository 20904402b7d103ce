#!/usr/bin/env bash
# LoCM ablation on synthetic scenes that pretraining never saw (evflow/benches/scenes/*.toml:
# other patterns, feature sizes, colours, texture seeds, speeds and camera paths than the
# pretraining presets × seeds 1–6). For each scene: `evflow finetune` in modes none, full
# and lora (defaults otherwise), then `evflow eval` against the scene's ground truth.
# Usage: evflow/benches/locm_table.sh [WORKDIR]   (release binaries in target/release)
# Env: MODES (default "none full lora"), SCENES (glob of scene names, default all),
#      EVFLOW_CONFIG (a FlowSettings TOML passed to finetune) with TAG (suffix of the
#      output directories, so runs with different settings do not reuse each other).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
bin="$root/target/release"
work="${1:-$root/target/locm-table}"
mkdir -p "$work"
printf '| scene | events | mode | EPE px/s | EPE px | zero-flow EPE px | outliers > 3 px | flow-warp gain | stage s |\n'
printf '|---|---:|---|---:|---:|---:|---:|---:|---:|\n'
modes="${MODES:-none full lora}"
tag="${TAG:-}"
cfgflag=()
[ -n "${EVFLOW_CONFIG:-}" ] && cfgflag=(--config "$EVFLOW_CONFIG")
for cfg in "$root"/evflow/benches/scenes/${SCENES:-*}.toml; do
  name="$(basename "$cfg" .toml)"
  [ -d "$work/$name" ] || "$bin/degs" synth --config "$cfg" --out "$work/$name" 2>/dev/null
  for mode in $modes; do
    out="$work/$name-$mode$tag"
    start=$(date +%s.%N)
    [ -d "$out" ] || "$bin/evflow" finetune --scene "$work/$name" --mode "$mode" "${cfgflag[@]}" --no-previews --out "$out" 2>/dev/null
    end=$(date +%s.%N)
    "$bin/evflow" eval --scene "$work/$name" --flows "$out" --out "$out.eval.json" >/dev/null 2>&1
    python3 - "$out" "$name" "$mode" "$start" "$end" "$tag" <<'PY'
import json, sys
out, name, mode, t0, t1, t = sys.argv[1:]
r = json.load(open(out + '/report.json'))
w = json.load(open(out + '.eval.json'))['windows']
n = sum(x['metrics']['count'] for x in w)
zero = sum(x['metrics']['gt_magnitude'] * x['metrics']['count'] for x in w) / n
print('| %s | %d | %s%s | %.2f | %.3f | %.3f | %.1f %% | %.3f | %.1f |' % (name, r['events'], mode, t,
      r['flow_epe_px_s'], r['flow_err_px'], zero, 100 * r['flow_outliers'], r['warp_gain'],
      r['wall_s']))
PY
  done
done
