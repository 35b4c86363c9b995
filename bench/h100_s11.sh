#!/usr/bin/env bash
# The device calls of session 11 (issue 16: the GPU feed schedules mixed episode lengths by length; fabric_1's tail
# profiled), run from the worktree copy on the H100 machine with the packages unpacked in /root/site:
# `bash bench/h100_s11.sh W|M|Q|S|G|F`. Logs and result files go to $OUT as one tar (at most 8 files come back).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack
mix() {  # tag, schedule: compact 6 x 6 mixed 0.1-2 Hz end to end (the command of -s9-mix-w / -s10-mix-ramp2)
    timeout 290 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --schedule $2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag $1 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/gpu-pipeline-$1.log | tail -2 | cut -c1-1500
    cp bench/results/gpu-pipeline-$1.json $OUT/r/
}
case "$1" in
W)  # a fresh machine: a small mixed run compiles MuJoCo Warp's kernels for the bench scene (not timed)
    timeout 300 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 2 --shard-episodes 256 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag warm 2>&1 | grep -v "^Module" | tail -1 | cut -c1-600
    pack W ;;
M)  # the mixed run scheduled by length (today's default), then by whole shards (session 10's batches): the A/B
    mix h100-s11-mix length
    mix h100-s11-mix-shards shards
    pack M ;;
L)  # the mixed run scheduled by length alone
    mix h100-s11-mix length
    pack L ;;
O)  # the mixed run by whole shards alone (session 10's batches)
    mix h100-s11-mix-shards shards
    pack O ;;
Q)  # the old single-frequency bench config (compact 6 x 6 at 0.5 Hz, 131072 episodes, as -s9-single-w): one
    # length, so the schedule is session 10's
    timeout 300 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --tag h100-s11-single \
        2>&1 | grep -v "^Module" | tee $OUT/r/logs/gpu-pipeline-h100-s11-single.log | tail -2 | cut -c1-1500
    cp bench/results/gpu-pipeline-h100-s11-single.json $OUT/r/
    pack Q ;;
S)  # fabric_1's driver stage alone on 8192 made-up episodes, profiled; then the transduction chain on CUDA
    timeout 200 python3 bench/bench_feed_stage.py --family fabric_1 --episodes ${2:-8192} --tag h100-s11 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/feed-stage-fabric_1-h100-s11.log | tail -80
    cp bench/results/feed-stage-fabric_1-h100-s11.json $OUT/r/
    timeout 150 python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s11 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/transduction-h100-s11.log | tail -4
    cp bench/results/transduction-h100-s11.json $OUT/r/
    pack S ;;
T)  # second machine: fabric_1's driver stage with load_batch's host passes on 1 and 4 threads, interleaved, not
    # profiled (the A/B of load_field.HOST_PASS_THREADS)
    timeout ${2:-240} python3 bench/bench_feed_stage.py --family fabric_1 --episodes 8192 --host-threads 1,4,1,4 --no-profile \
        --tag h100-s11-threads 2>&1 | grep -v "^Module" | tee $OUT/r/logs/feed-stage-fabric_1-h100-s11-threads.log | tail -6
    cp bench/results/feed-stage-fabric_1-h100-s11-threads.json $OUT/r/
    pack T ;;
G)  # pytest -m gpu on this session's code
    timeout ${2:-400} python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-h100-s11.log | tail -12
    echo "pytest rc $?" | tee -a $OUT/r/logs/pytest-gpu-h100-s11.log
    pack G ;;
F)  # the plain CLI of fabric_1 with MuJoCo Warp alone
    cli fabric_1 ${2:-8192} h100-s11-fabric
    pack F ;;
esac
