#!/bin/bash
# The training queue (docs/training/README.md). One command starts or resumes it in the
# background; run it first whenever work on the project begins:
#
#   bash runs/train.sh          # start or resume the queue (background; log in runs/queue.out)
#   bash runs/train.sh status   # where each run stands
#   bash runs/train.sh stop     # stop it (every run resumes from its last checkpoint)
#   bash runs/train.sh snapshot # before committing a stopped queue: weights and Adam moments in
#                               # bf16, no Adam state for runs at their last target
#
# The queue trains one run at a time on all cores, in the order below: each run until its
# target epoch (`rgm train --until-epoch`), then the next. Every run is resumable, so stopping
# anywhere loses at most one checkpoint interval. Raise a target (or add a line) to give a run
# more epochs; a run's other options must stay as they started (`rgm train` checks).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${RGM_DATA:-../shared/data/modelnet40_npy1024}"
COMMON="--preset fast --optimizer adam --lr 3e-4 --val-shapes 300 --checkpoint-every 50 --test-statistics cloud"
# name | target epoch | options besides $COMMON
# The runs this queue trained before are finished or retired (partial-fast to epoch 100 on the
# schedule --epochs 100 --milestones 60,80; noise-fast, clean-fast, var2-fast, unseen-fast,
# var1-fast; partial-fast-200, retired at epoch 23 once training on whole clouds won, session
# 26): their folders have left the working tree and are in the history. docs/training/README.md
# has each run's page and the queue's order and targets; the weights the tables use are the
# manifest's git:REV:PATH files. Listed here again, a run whose folder is missing would start
# from scratch.
QUEUE=(
  # The built-in model's run: trained on whole clouds (717 points; 384 lost an equal-time A/B by
  # 7.5 points of validation recall) in two GPU windows (tools/gpu/window.sh, docs/training/gpu.md),
  # carried on here between windows. bf16 products where the processor has AMX or AVX-512 BF16.
  # `--init` is read only when a run starts (a folder without state.json; `Trainer::open`) and
  # must stay as config.json spells it: window 1's last weights, which are not committed.
  "partial-fast-717|200|--setting partial --match-points 0 --batch 32 --epochs 200 --milestones 5,7 --val-sample spread --init target/gpu-init/partial717-w1.safetensors --precision bf16"
)

status() {
  python3 - "${QUEUE[@]}" <<'EOF'
import json, os, sys, time
print(f"{'run':<14}{'epoch':>7}{'target':>8}{'pairs seen':>12}{'pairs/s':>9}"
      f"{'last validation (recall / refined / MIE(R))':>46}  to target")
seen = set()
for entry in sys.argv[1:]:
    name, target, _ = entry.split("|", 2)
    target = int(target)
    if (name, target) in seen:
        continue
    seen.add((name, target))
    folder = os.path.join("runs", name)
    try:
        state = json.load(open(os.path.join(folder, "state.json")))
    except FileNotFoundError:
        print(f"{name:<14}{'-':>7}{target:>8}{'not started':>12}")
        continue
    records = [json.loads(l) for l in open(os.path.join(folder, "log.jsonl")) if l.strip()]
    train = [r for r in records if r["kind"] == "train"]
    vals = [r for r in records if r["kind"] == "validation"]
    rate = 0.0
    if len(train) >= 2:
        recent = train[-20:]
        dp = recent[-1]["pairs_seen"] - recent[0]["pairs_seen"]
        dt = recent[-1]["seconds"] - recent[0]["seconds"]
        rate = dp / dt if dt > 0 else 0.0
    val = "-"
    if vals:
        v = vals[-1]
        val = (f"epoch {v['epoch'] + 1}: {100 * v['recall']:.1f} % / "
               f"{100 * v.get('recall_refined', 0):.1f} % / {v['mie_r_deg']:.1f}°")
    epoch = state["epoch"] + state["batch"] / max(train[-1]["batches"], 1) if train else 0
    left = "done" if state["epoch"] >= target else "-"
    if state["epoch"] < target and rate > 0 and train:
        pairs_left = (target - epoch) * train[-1]["batches"] * 4
        left = f"{pairs_left / rate / 3600:.1f} h"
    print(f"{name:<14}{epoch:>7.2f}{target:>8}{state['pairs_seen']:>12,}{rate:>9.2f}{val:>46}  {left}")
pid_file = "runs/queue.pid"
if os.path.exists(pid_file):
    pid = int(open(pid_file).read())
    alive = os.path.exists(f"/proc/{pid}")
    print(f"queue: {'running' if alive else 'not running'} (pid {pid}); log runs/queue.out")
else:
    print("queue: not running; start it with bash runs/train.sh")
EOF
}

run_queue() {
  for entry in "${QUEUE[@]}"; do
    IFS='|' read -r name target options <<<"$entry"
    [ -e runs/queue.stop ] && break
    mkdir -p "runs/$name"
    echo "$(date -u +%FT%TZ) $name until epoch $target"
    # shellcheck disable=SC2086
    runs/rgm-train train --data "$DATA" --out "runs/$name" $COMMON $options \
      --until-epoch "$target" >>"runs/$name/train.out" 2>&1 || {
      echo "$(date -u +%FT%TZ) $name failed (see runs/$name/train.out); queue stopped"
      exit 1
    }
  done
  rm -f runs/queue.stop
  echo "$(date -u +%FT%TZ) queue done"
}

case "${1:-start}" in
  status) status ;;
  stop)
    # A checkpoint is one atomic commit every 50 batches: a stop loses at most that much work.
    touch runs/queue.stop
    [ -f runs/queue.pid ] && kill "$(cat runs/queue.pid)" 2>/dev/null || true
    pkill -TERM -f "runs/rgm-train train" || true
    echo "queue stopped" ;;
  start)
    if [ -f runs/queue.pid ] && kill -0 "$(cat runs/queue.pid)" 2>/dev/null; then
      echo "the queue is already running (pid $(cat runs/queue.pid))"; exit 0
    fi
    rm -f runs/queue.stop
    # A frozen copy of the binary, so rebuilding the workspace does not touch the running job.
    cargo build --release --bin rgm
    cp target/release/rgm runs/rgm-train.new && mv runs/rgm-train.new runs/rgm-train
    nohup bash "$0" run-queue >>runs/queue.out 2>&1 &
    echo $! >runs/queue.pid
    echo "training queue in the background, pid $(cat runs/queue.pid); bash runs/train.sh status" ;;
  snapshot)
    # Runs at the last target the queue gives them are committed without their Adam state.
    finished=()
    declare -A final
    for entry in "${QUEUE[@]}"; do
      IFS='|' read -r name target _ <<<"$entry"
      final[$name]=$target
    done
    for name in "${!final[@]}"; do
      [ -f "runs/$name/state.json" ] || continue
      epoch=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["epoch"])' "runs/$name/state.json")
      [ "$epoch" -ge "${final[$name]}" ] && finished+=("$name")
    done
    cargo xtask snapshot-runs ${finished:+--finished "${finished[@]}"} ;;
  run-queue) run_queue ;;
  *) echo "usage: bash runs/train.sh [start|status|stop|snapshot]" >&2; exit 2 ;;
esac
