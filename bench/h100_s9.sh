#!/usr/bin/env bash
# The device calls of session 9 (issue 16: velostat's sensor stage on the device, fabric's first batch streamed
# while it steps), run from the worktree copy on the H100 machine with the packages unpacked in /root/site:
# `bash bench/h100_s9.sh A|B|C|F|M|N|S|W|X`. Logs and result files go to $OUT as one tar (at most 8 files come back).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack
case "$1" in
A)  # pytest -m gpu on the final code (compiles MuJoCo Warp's kernels for every family's scene: the CLI runs after
    # are warm), then the plain CLI of velostat (its sensor stage on the device now) with MuJoCo Warp alone
    timeout ${2:-300} python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-h100-s9.log | tail -12
    echo "pytest rc $?" | tee -a $OUT/r/logs/pytest-gpu-h100-s9.log
    cli velostat ${3:-8192} h100-s9-velostat
    pack A ;;
F)  # the plain CLI of fabric_1 (its first batch's sensor chain streamed while the worlds step) with MuJoCo Warp alone
    cli fabric_1 ${2:-8192} h100-s9-fabric
    pack F ;;
M)  # compact 6 x 6 mixed 0.1-2 Hz end to end (same command as -s7-mix-final / -s8-mix; cnt_pdms on the convex
    # collider again), then the transduction chain on CUDA
    timeout 330 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s9-mix 2>&1 | tee $OUT/r/logs/gpu-pipeline-h100-s9-mix.log | tail -3
    cp bench/results/gpu-pipeline-h100-s9-mix.json $OUT/r/
    timeout 150 python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s9 2>&1 | tee $OUT/r/logs/transduction-h100-s9.log | tail -4
    cp bench/results/transduction-h100-s9.json $OUT/r/
    pack M ;;
B)  # second machine, final code (the recorded taxel fields rounded to float32 on the device and copied back through
    # page-locked buffers): pytest -m gpu, then the plain CLI of velostat with MuJoCo Warp alone
    timeout ${2:-300} python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-h100-s9-final.log | tail -12
    echo "pytest rc $?" | tee -a $OUT/r/logs/pytest-gpu-h100-s9-final.log
    cli velostat ${3:-8192} h100-s9-velostat-f32
    pack B ;;
C)  # final code: the plain CLI of cnt_pdms (15 x 15 fields recorded) and fabric_1
    cli cnt_pdms ${2:-4096} h100-s9-cnt-f32 noalone
    pack C ;;
N)  # if time allows: ntype and cnt_pdms plain CLI
    cli ntype ${2:-4096} h100-s9-ntype noalone
    cli cnt_pdms ${3:-4096} h100-s9-cnt noalone
    pack N ;;
S)  # the old single-frequency bench config (as -s5-single: compact 6 x 6 at 0.5 Hz, 196608 episodes) on this
    # session's code, so the headline's end-to-end figure is one run of today's code, not a best-ever
    timeout 400 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --tag h100-s9-single \
        2>&1 | tee $OUT/r/logs/gpu-pipeline-h100-s9-single.log | tail -3
    cp bench/results/gpu-pipeline-h100-s9-single.json $OUT/r/
    pack S ;;
X)  # the compact 6 x 6 mixed-frequency run again (as M's first part): its spread between two runs of one code
    timeout 400 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s9-mix-b 2>&1 | tee $OUT/r/logs/gpu-pipeline-h100-s9-mix-b.log | tail -3
    cp bench/results/gpu-pipeline-h100-s9-mix-b.json $OUT/r/
    pack X ;;
W)  # after the writer's digest change (attributes decoded in memory): a small run compiles the kernels (a fresh
    # machine), then the single-frequency bench config as S, tag -s9-single-w
    timeout 300 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 2 --shard-episodes 1024 --tag warm 2>&1 | tail -1
    timeout 400 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --tag h100-s9-single-w \
        2>&1 | tee $OUT/r/logs/gpu-pipeline-h100-s9-single-w.log | tail -3
    cp bench/results/gpu-pipeline-h100-s9-single-w.json $OUT/r/
    pack W ;;
esac
