#!/usr/bin/env bash
# The device calls of session 10 (issue 16: ntype's taxel fields and element loads on the device; fabric's
# streamed first batch A/B), run from the worktree copy on the H100 machine with the packages unpacked in
# /root/site: `bash bench/h100_s10.sh I|A|F|G|M`. Logs and result files go to $OUT as one tar (at most 8 files come back).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack
case "$1" in
I)  # a fresh machine: pytest -m gpu (compiles MuJoCo Warp's kernels for every family's scene, so the CLI runs
    # after are warm; checks the new ntype device path against the host path on CUDA)
    timeout ${2:-330} python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-h100-s10.log | tail -12
    echo "pytest rc $?" | tee -a $OUT/r/logs/pytest-gpu-h100-s10.log
    pack I ;;
A)  # the plain CLI with today's code: ntype (its taxel fields and element loads on the device), cnt_pdms, velostat
    # (with MuJoCo Warp alone)
    cli ntype ${2:-8192} h100-s10-ntype noalone
    cli cnt_pdms ${3:-4096} h100-s10-cnt noalone
    cli velostat ${4:-8192} h100-s10-velostat
    pack A ;;
F)  # the plain CLI of fabric_1, first batch streamed (the default), with MuJoCo Warp alone
    cli fabric_1 ${2:-8192} h100-s10-fabric
    pack F ;;
G)  # the same with the stream off (PIEZOTWIN_FEED_STREAM=0, commit 8c879ca; the stream is gone since): the A/B
    export PIEZOTWIN_FEED_STREAM=0; cli fabric_1 ${2:-8192} h100-s10-fabric-nostream noalone
    pack G ;;
M)  # compact 6 x 6 mixed 0.1-2 Hz end to end (the command of -s9-mix-w) on today's code, then the same with a
    # smaller first batch (--ramp-batches 3: worlds / 8, worlds / 4, worlds / 2 before the full ones), so the
    # driver and the writers start sooner while the later batches step
    timeout 200 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 2 --shard-episodes 1024 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag warm 2>&1 | tail -1  # kernels compiled, not timed
    for r in 2 3; do
        timeout 270 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --ramp-batches $r \
            --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s10-mix-ramp$r 2>&1 | grep -v "^Module" \
            | tee $OUT/r/logs/gpu-pipeline-h100-s10-mix-ramp$r.log | tail -3
        cp bench/results/gpu-pipeline-h100-s10-mix-ramp$r.json $OUT/r/
    done
    pack M ;;
esac
