#!/usr/bin/env bash
# The device calls of session 13 (issue 16: fabric_1's plain CLI with the manifest from the writers' entries; the
# compact 6 x 6 mixed bench re-run; the fused taxel kernel's approximate divisions / exp on CUDA), run from the
# worktree copy on the H100 machine with the packages unpacked in /root/site: `bash bench/h100_s13.sh F|M|X|G [n]`.
# Logs and result files go to $OUT as one tar per mode (at most 8 files come back).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack
case "$1" in
F)  # fabric_1: a 256-episode warm-up run (compiles its kernels, not timed), then the plain CLI + stepping alone
    timeout 250 python3 bench/bench_user_cli.py --families fabric_1 --episodes 256 --tag warm-fabric 2>&1 | grep -v "^Module" | tail -1 | cut -c1-300
    cli fabric_1 ${2:-8192} h100-s13-fabric; pack F ;;
M)  # compact 6 x 6 mixed 0.1-2 Hz end to end (session 11's command, -s11-mix), after a small mixed warm-up run
    timeout 200 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 2 --shard-episodes 256 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag warm 2>&1 | grep -v "^Module" | tail -1 | cut -c1-300
    timeout 290 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --schedule length \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s13-mix 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/gpu-pipeline-h100-s13-mix.log | tail -2 | cut -c1-2500
    cp bench/results/gpu-pipeline-h100-s13-mix.json $OUT/r/
    pack M ;;
X)  # the transduction chain on CUDA (the fused kernel as built by default), then the fused kernel's math variants
    timeout 200 python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s13 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/transduction-h100-s13.log | tail -6 | cut -c1-3000
    cp bench/results/transduction-h100-s13.json $OUT/r/
    if [ -f bench/fused_math.py ]; then
        timeout 200 python3 bench/fused_math.py --out $OUT/r/fused-math-h100-s13.json 2>&1 | grep -v "^Module" | tail -12
    fi
    pack X ;;
G)  # the GPU tests of the fused kernel, the full chain and the readout
    timeout ${2:-300} python3 -m pytest tests/test_gpu.py -q -m gpu -p no:cacheprovider -k "fused or readout or full_chain or approx" 2>&1 \
        | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-h100-s13.log | tail -6
    pack G ;;
esac
