#!/usr/bin/env bash
# The velostat experiment at the full budget (issue 14) on the device machine, seeds 0-2 side by side, for the
# coordinator: run from the repository copy's root.
#   bash bench/device_full_velostat.sh start     launches one process per seed (setsid nohup) and returns at once;
#                                                 each makes its own data (the seed sets the data, as the CLI's
#                                                 --seed does), trains the paper's chains (BP searches in CPU worker
#                                                 processes) and ours (TCN ensemble on the GPU: --train-device cuda
#                                                 for ours only, recorded in the results)
#   bash bench/device_full_velostat.sh poll      prints progress every 30 s for up to 540 s; returns early when
#                                                 every seed's process has ended
#   bash bench/device_full_velostat.sh collect   writes bench/results/experiments/velostat-full[-seedS].json (the
#                                                 shape docs/gen reads; partial runs say so) and packs them with the
#                                                 logs and reports into $OUT/velostat-full.tgz (one file)
# Environment (defaults for the device): VF_MODE=full, VF_SEEDS="0 1 2", VF_WORKERS="4 2 2" (BP worker processes
# per seed, in seed order; ~8 of the 16 cores: ntype's full run shares the machine), VF_THREADS=1 (generation
# threads per seed: the same arrays at any count, but the count is in the recorded config, so 1 keeps the data
# fingerprints equal to session 9's full record and its chains comparable number for number), VF_RUN=runs/velostat-full, VF_DEST=bench/results/experiments, VF_TCN=auto, VF_TCN_WORKERS=3
# (ours' three input sets side by side, one process each), VF_POLL_S=540.
# Estimate (scaled from local runs on 2 shared cores: session 9's full data 266 s wall and BP searches ~1160 CPU-s
# in all; this session's quick run with 2 BP workers), for ~8 cores and one H100: data ~3 min per seed (one
# generation thread), the paper's chains ~5 min (seed 0, 4 BP workers) / ~8 min (seeds 1-2, 2 workers), ours
# (9 TCN members of <= 200 epochs x ~470 batches; its 3 input sets side by side, ~1-2 s an epoch on the GPU)
# ~5-8 min: seed 0 complete in ~16 min, seeds 1-2 in ~19-21 min. A seed still training when the machine goes
# back leaves a metrics.json marked partial (the paper's chains are tested before ours trains); collect takes it.
#
# VF_ONLY=ours (session 11): ours only, merged into the recorded velostat-$VF_MODE[-seedS].json (whose chains stay as
# recorded). start: per seed the same data again (each folder's shards in VF_GEN_WORKERS processes, default 5), the
# creep tracker, the units and the two BP chains ours' inputs read (raw_bp, paper_unit; VF_WORKERS processes each,
# default "5 5 5"), then ours: its 3 input sets x 3 members as ONE batched network on the GPU (one GPU process per
# seed). collect: `device_full_velostat.py merge` checks each seed's data (content and config hashes per folder)
# and split against the record and merges ours, or refuses that seed (the record untouched, exit 3), then packs
# the records and logs into $OUT/velostat-$VF_MODE.tgz. Default run folder runs/velostat-$VF_MODE-ours.
# Estimate for 16 cores + one H100 (local measurements scaled, see bench/device_full_velostat.txt): data ~1-2 min, chains ~2 min,
# ours ~2-5 min (<= 200 epochs of ~460 batches at ~2-3 ms a step); seeds 0-2 side by side ~8-10 min.
set -u
cd "$(dirname "$0")/.."
export PYTHONPATH=${PYTHONPATH:-/root/site:.} PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=${PY:-python3}
MODE=${VF_MODE:-full}
SEEDS=(${VF_SEEDS:-0 1 2})
ONLY=${VF_ONLY:-}
if [ "$ONLY" = ours ]; then
    WORKERS=(${VF_WORKERS:-5 5 5})
    EXTRA="--ours-only --gen-workers ${VF_GEN_WORKERS:-5}"
    RUN=${VF_RUN:-runs/velostat-$MODE-ours}
elif [ -n "$ONLY" ]; then
    echo "VF_ONLY must be empty or 'ours' (got '$ONLY')" >&2; exit 2
else
    WORKERS=(${VF_WORKERS:-4 2 2})
    EXTRA=""
    RUN=${VF_RUN:-runs/velostat-$MODE}
fi
THREADS=${VF_THREADS:-1}
DEST=${VF_DEST:-bench/results/experiments}
TCN=${VF_TCN:-auto}
OUTDIR=${OUT:-$RUN/out}

alive() {  # seed -> 0 when its process still runs
    local f=$RUN/seed$1.pid
    [ -f "$f" ] && kill -0 "$(cat "$f")" 2>/dev/null
}

case "${1:-}" in
start)
    mkdir -p "$RUN"
    git rev-parse --short HEAD > "$RUN/commit" 2>/dev/null || echo "${VF_COMMIT:-unknown}" > "$RUN/commit"
    date -u +%s > "$RUN/t0"
    for i in "${!SEEDS[@]}"; do
        s=${SEEDS[$i]}; w=${WORKERS[$i]:-2}
        if alive "$s"; then echo "seed $s already running (pid $(cat $RUN/seed$s.pid))"; continue; fi
        # seeds after the first start ${VF_STAGGER_S:-20} s apart (in the background: start returns at once), so
        # that Warp's kernel cache is filled by one process first
        setsid nohup bash -c "sleep $(( i * ${VF_STAGGER_S:-20} )); exec $PY bench/device_full_velostat.py run \
            --seed $s --mode $MODE --out $RUN/seed$s --workers $w --tcn-device $TCN \
            --tcn-workers ${VF_TCN_WORKERS:-3} --set generation.threads=$THREADS $EXTRA" \
            > "$RUN/seed$s.log" 2>&1 < /dev/null &
        echo $! > "$RUN/seed$s.pid"
        echo "seed $s: pid $!, $w BP workers, log $RUN/seed$s.log"
    done
    ;;
poll)
    end=$(( $(date -u +%s) + ${VF_POLL_S:-540} ))
    while :; do
        now=$(date -u +%s); n=0
        echo "--- $(( now - $(cat $RUN/t0 2>/dev/null || echo $now) )) s since start; load $(cut -d' ' -f1-3 /proc/loadavg)"
        for s in "${SEEDS[@]}"; do
            if alive "$s"; then n=$((n + 1)); st=running; else st=ended; fi
            echo "seed $s ($st): $(grep -v '^\s*$' $RUN/seed$s.log 2>/dev/null | grep '^\[' | tail -1 | cut -c1-200)"
        done
        nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader 2>/dev/null | sed 's/^/gpu: /'
        [ "$n" -eq 0 ] && { echo "all seeds ended"; for s in "${SEEDS[@]}"; do tail -3 "$RUN/seed$s.log"; done; exit 0; }
        [ "$now" -ge "$end" ] && exit 0
        sleep $(( end - now < 30 ? end - now : 30 ))
    done
    ;;
collect)
    rc=0
    # wait (up to VF_COLLECT_WAIT_S, default 240 s) until every seed's process has ended and its log says "done"
    # (session 11's first collect ran seconds before the last seed's "done"); a seed without "done" is reported here
    # and its run.json is not marked finished, so merge refuses it (exit 3)
    end=$(( $(date -u +%s) + ${VF_COLLECT_WAIT_S:-240} ))
    while :; do
        left=""
        for s in "${SEEDS[@]}"; do
            if alive "$s" || ! grep -q '\] done:' "$RUN/seed$s.log" 2>/dev/null; then left="$left $s"; fi
        done
        [ -z "$left" ] && { echo "every seed done: ${SEEDS[*]}"; break; }
        [ "$(date -u +%s)" -ge "$end" ] && { echo "NOT DONE after ${VF_COLLECT_WAIT_S:-240} s: seeds$left"; break; }
        alive_any=0; for s in $left; do alive "$s" && alive_any=1; done
        [ "$alive_any" -eq 0 ] && { echo "ENDED WITHOUT \"done\": seeds$left (see their logs)"; break; }
        echo "waiting for seeds$left to finish"; sleep 10
    done
    if [ "$ONLY" = ours ]; then
        $PY bench/device_full_velostat.py merge --run "$RUN" --dest "$DEST" --mode "$MODE" \
            --commit "$(cat $RUN/commit 2>/dev/null || echo unknown)" || rc=$?
    else
        $PY bench/device_full_velostat.py collect --run "$RUN" --dest "$DEST" --mode "$MODE" \
            --commit "$(cat $RUN/commit 2>/dev/null || echo unknown)"
    fi
    mkdir -p "$OUTDIR"
    files=$(ls $DEST/velostat-$MODE.json $DEST/velostat-$MODE-seed*.json 2>/dev/null)
    extra=$(cd "$RUN" && ls seed*.log seed*/run.json seed*/report.md $([ "$ONLY" = ours ] && echo "seed*/metrics.json") \
        2>/dev/null | sed "s|^|$RUN/|")
    tar czf "$OUTDIR/velostat-$MODE.tgz" $files $extra
    ls -la "$OUTDIR/velostat-$MODE.tgz"; tar tzf "$OUTDIR/velostat-$MODE.tgz"
    exit $rc
    ;;
*)
    echo "usage: $0 start|poll|collect" >&2; exit 2 ;;
esac
