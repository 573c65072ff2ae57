#!/usr/bin/env bash
# rgm register's default (the cascade), the same with both methods on every pair (--accept inf),
# and Open3D RANSAC + ICP on the same ModelNet40 test pairs, one thread each, one after the other
# in one run (docs/baselines.md, "The cascade").
#   bash tools/baselines/modelnet_default.sh [SETTING] [EVERY] [OUT]   (partial, 10, /tmp/rgm-default)
# SETTING: partial, noise or clean. Needs target/release/rgm (cargo build --release) and open3d 0.20
# (pip install open3d-cpu==0.20.0). On a machine busy with other work, run it as root so that its
# processes get their share of a core first (it raises their autogroup's priority).
set -euo pipefail
setting=${1:-partial}
every=${2:-10}
out=${3:-/tmp/rgm-default}/$setting
data=${RGM_DATA:-../shared/data/modelnet40_npy1024}
export OPENBLAS_NUM_THREADS=1 RAYON_NUM_THREADS=1 OMP_NUM_THREADS=1
echo -10 >/proc/self/autogroup 2>/dev/null || true
rgm=target/release/rgm
mkdir -p "$out"
"$rgm" pairs --setting "$setting" --every "$every" --out "$out/pairs" --data "$data" >/dev/null
for accept in default inf; do
  opt=(); [ "$accept" = default ] || opt=(--accept "$accept")
  "$rgm" eval --method auto --refine "${opt[@]}" --setting "$setting" --every "$every" \
    --workers 1 --data "$data" --json "$out/rgm-accept-$accept.json" 2>/dev/null | tail -n 1
done
rm -f "$out/candidates.jsonl"
# The candidates each pair ran: `rgm register --pairs` reads the pairs.json of `rgm pairs`.
"$rgm" --threads 1 register --pairs "$out/pairs/pairs.json" --output "$out/candidates.jsonl" >/dev/null 2>&1 || true
python3 - "$out/candidates.jsonl" <<'EOF'
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
network = sum(any(c["method"].startswith("rgm") for c in l["candidates"]) for l in lines)
print(f"the default ran the network on {network} of {len(lines)} pairs ({100 * network / len(lines):.1f} %)")
EOF
python3 tools/open3d/register_pairs.py "$out/pairs" --method ransac_icp --out "$out/open3d-ransac-icp.json" >/dev/null
"$rgm" score "$out/open3d-ransac-icp.json" --pairs "$out/pairs" | tail -n 1
