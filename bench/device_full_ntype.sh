#!/usr/bin/env bash
# ntype at the full budget on the device machine (issue 14, ntype part; session 10): the paper's task, the
# paper's 3000 samples, 10 folds, training seeds 0-2, every model: Table 1 (eq. 9 + RLS, eqs. 10-12 as printed),
# the sliding windows 1 / 3 / 5 / 7, the element MLP (ours) and the map CNN. press_stroke is not run at full.
# Run from the repo copy's root:
#
#   bash bench/device_full_ntype.sh start    # generates the data (seconds), launches the parts, returns at once
#   bash bench/device_full_ntype.sh poll     # up to 540 s: progress every 30 s, returns when every part is done
#   bash bench/device_full_ntype.sh collect  # merges the finished parts into bench/results/experiments/
#                                            # ntype-full.json, -seed1, -seed2 and tars them + logs into $OUT
#   bash bench/device_full_ntype.sh stop     # ends the parts still running (by the pids start wrote)
#
# One process per (seed, part): emlp = the element MLP (ours) and cnn = the map CNN (ours, first attempt), each
# with --train-device $NTYPE_GPU (cuda when nvidia-smi answers); w3 / w7 / w5 / w1 = one window of rbf_win
# each; t1 = Table 1 (rbf_col, eq9 + eq9+exact, the readings session 9 ran at full). One thread each (OMP / MKL /
# OpenBLAS / torch). Oversubscribed on purpose (21 processes for ~8 cores): nice levels finish what the targets
# need first (ours and windows 3 / 7 at nice 0, Table 1 and window 5 at 2 - both recorded by session 9 on these
# seeds - the map CNN at 3, window 1, our extra row, at 4). collect merges whatever finished; a Table 1 / window 5
# part that did not is taken from ntype-full-paper[-seedN].json only if that ran on the same dataset and folds.
# Expected (CHANGELOG "ntype, session 10"): ~5800 CPU-s in all - Table 1 ~400 and each window ~300 CPU-s a seed
# (session 9's full runs of Table 1 and window 5 on 2 shared cores), the GPU parts ~1 core each while they run -
# so 12-15 min wall on 8 free cores; the element MLP ~171k batched steps a seed (5 members, 10 folds, <= 100
# epochs): ~3-5 min on the H100 at ~1-2 ms a step (33 min a seed on one CPU core: measured 2 CPU-s an epoch).
#
# Knobs (environment): NTYPE_MODE=full|tiny (tiny: a seconds-long test of the script), NTYPE_SEEDS="0 1 2",
# NTYPE_PARTS="emlp cnn w3 w7 w5 t1 w1", NTYPE_GPU=cuda|cpu|auto, NTYPE_ROOT=runs/ntype-full-dev, PY=python3.
set -u
export PYTHONPATH=/root/site:.${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMEXPR_NUM_THREADS=1
PY=${PY:-python3}
MODE=${NTYPE_MODE:-full}
SEEDS=${NTYPE_SEEDS:-0 1 2}
PARTS=${NTYPE_PARTS:-emlp cnn w3 w7 w5 t1 w1}
ROOT=${NTYPE_ROOT:-runs/ntype-full-dev}
OUTDIR=${OUT:-$ROOT/out}
if [ -z "${NTYPE_GPU:-}" ]; then
    if nvidia-smi -L >/dev/null 2>&1; then NTYPE_GPU=cuda; else NTYPE_GPU=cpu; fi
fi

part_args() {  # part -> the arguments of bench/ntype_full_part.py and its nice level
    case "$1" in
        emlp) echo "0 --models elem_mlp --train-device $NTYPE_GPU" ;;
        cnn) echo "3 --models map_cnn --train-device $NTYPE_GPU" ;;
        w1|w3|w5|w7) n=${1#w}; lvl=0; [ "$n" = 5 ] && lvl=2; [ "$n" = 1 ] && lvl=4
                     echo "$lvl --models rbf_win --windows $n" ;;
        t1) echo "2 --models rbf_col --alts eq9+exact" ;;
        *) echo "unknown part $1" >&2; return 1 ;;
    esac
}

start() {
    for p in $PARTS; do part_args "$p" > /dev/null || exit 2; done
    if [ -d "$ROOT/parts" ] && ls "$ROOT"/parts/*/pid >/dev/null 2>&1; then
        for d in "$ROOT"/parts/*/; do
            if [ -f "$d/pid" ] && kill -0 "$(cat "$d/pid")" 2>/dev/null; then echo "parts still running under $ROOT (stop first)"; exit 1; fi
        done
    fi
    mkdir -p "$ROOT/logs" "$ROOT/parts" "$ROOT/data"
    date +%s > "$ROOT/t_start"
    echo "$PARTS" > "$ROOT/part_names"
    echo "$SEEDS" > "$ROOT/seed_names"
    for s in $SEEDS; do  # the data once per seed (a few seconds each), then a private copy per part (no shared manifest)
        $PY -c "
import sys
from pathlib import Path
from learn.experiments import ntype as NT
from learn.experiments.common import make_data
md = NT.MODES['$MODE']
make_data(Path('$ROOT/data/s$s/paper'), NT.scene(md, [], $s, 'paper'), print)
" > "$ROOT/logs/gen-s$s.log" 2>&1 || { echo "data generation failed for seed $s:"; tail -5 "$ROOT/logs/gen-s$s.log"; exit 1; }
        tail -1 "$ROOT/logs/gen-s$s.log"
    done
    for s in $SEEDS; do
        for p in $PARTS; do
            set -- $(part_args "$p")
            lvl=$1; shift
            d="$ROOT/parts/s$s-$p"
            rm -rf "$d"; mkdir -p "$d"; cp -r "$ROOT/data/s$s" "$d/data"
            hide=(); case "$p" in emlp|cnn) ;; *) hide=(env CUDA_VISIBLE_DEVICES=) ;; esac  # CPU parts: no CUDA context
            setsid nohup nice -n "$lvl" "${hide[@]}" $PY bench/ntype_full_part.py --seed "$s" --mode "$MODE" --out "$d/out" \
                --data "$d/data" "$@" > "$ROOT/logs/s$s-$p.log" 2>&1 < /dev/null &
            echo $! > "$d/pid"
        done
    done
    echo "launched $(ls -d "$ROOT"/parts/*/ | wc -l) parts (mode $MODE, seeds $SEEDS, gpu parts on $NTYPE_GPU) under $ROOT"
}

status() {  # prints one line per part; returns 0 when none is running
    local running=0
    for d in "$ROOT"/parts/*/; do
        p=$(basename "$d")
        if [ -f "$d/out/run_info.json" ]; then
            st=$(grep -o '"status": "[a-z]*"' "$d/out/run_info.json" | cut -d'"' -f4)
            cpu=$(grep -o '"cpu_s": [0-9.]*' "$d/out/run_info.json" | cut -d' ' -f2)
            echo "  $p: $st (${cpu%.*} CPU-s)"
        elif [ -f "$d/pid" ] && kill -0 "$(cat "$d/pid")" 2>/dev/null; then
            running=$((running + 1))
            echo "  $p: running, $(grep -a 'fold' "$ROOT/logs/$p.log" | tail -1 | cut -c1-150)"
        else
            echo "  $p: ended without run_info: $(tail -1 "$ROOT/logs/$p.log" | cut -c1-150)"
        fi
    done
    echo "  $(( $(date +%s) - $(cat "$ROOT/t_start") )) s since start; $running running; load $(cut -d' ' -f1-3 /proc/loadavg)"
    [ "$running" = 0 ]
}

poll() {
    local t0; t0=$(date +%s)
    while true; do
        if status > "$ROOT/status.txt"; then cat "$ROOT/status.txt"; echo "all parts ended"; return 0; fi
        if [ $(( $(date +%s) - t0 )) -ge "${1:-540}" ]; then cat "$ROOT/status.txt"; return 0; fi
        echo "$(date -u +%H:%M:%S) $(grep -c ': done' "$ROOT/status.txt") done, $(grep -c ': running' "$ROOT/status.txt") running, $(grep -c 'ended without\|failed' "$ROOT/status.txt") failed; $(tail -1 "$ROOT/status.txt")"
        sleep 30
    done
}

collect() {
    status || echo "(some parts still running: collecting what finished)"
    local last; last=$(stat -c %Y "$ROOT"/parts/*/out/run_info.json 2>/dev/null | sort -n | tail -1)
    local wall=$(( ${last:-$(date +%s)} - $(cat "$ROOT/t_start") ))
    local seeds; seeds=$(tr ' ' ',' < "$ROOT/seed_names" | sed 's/,$//')
    local parts; parts=$(tr ' ' ',' < "$ROOT/part_names" | sed 's/,$//')
    $PY bench/ntype_full_merge.py --root "$ROOT" --seeds "$seeds" --parts "$parts" --wall-s "$wall" \
        ${NTYPE_RESULTS:+--results "$NTYPE_RESULTS"} 2>&1 | tee "$ROOT/logs/merge.log"
    mkdir -p "$OUTDIR"
    local res=${NTYPE_RESULTS:-bench/results/experiments}
    local files=()
    for s in ${SEEDS}; do [ "$s" = 0 ] && files+=("$res/ntype-full.json") || files+=("$res/ntype-full-seed$s.json"); done
    tar czf "$OUTDIR/ntype-full-device.tgz" "${files[@]}" "$ROOT"/logs "$ROOT/status.txt" \
        $(ls "$ROOT"/parts/*/out/run_info.json "$ROOT"/parts/*/out/metrics.json "$ROOT"/parts/*/out/report.md 2>/dev/null)
    ls -la "$OUTDIR/ntype-full-device.tgz"
}

stop() {
    for d in "$ROOT"/parts/*/; do
        [ -f "$d/pid" ] && kill -0 "$(cat "$d/pid")" 2>/dev/null && kill "$(cat "$d/pid")" && echo "stopped $(basename "$d")"
    done
    return 0
}

case "${1:-}" in
    start) start ;;
    poll) poll "${2:-540}" ;;
    collect) collect ;;
    stop) stop ;;
    status) status; true ;;
    *) echo "usage: $0 start|poll [seconds]|collect|stop|status" >&2; exit 2 ;;
esac
