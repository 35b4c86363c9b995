#!/usr/bin/env bash
# The device calls of session 6 (issue 16), run from the worktree copy on the H100 machine with the packages
# unpacked in /root/site: `bash bench/h100_s6.sh A|B`. Logs and result files go to $OUT.
export PYTHONPATH=/root/site:. PYTHONUNBUFFERED=1 OMP_NUM_THREADS=4
set -o pipefail
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv,noheader
case "$1" in
A)  # gpu tests on the final kernels, the transduction chain before/after, fabric workers 1 vs 8
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s6 2>&1 | tee $OUT/transduction-h100-s6.log
    cp bench/results/transduction-h100-s6.json $OUT/
    timeout 300 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s6.log | tail -25
    echo "pytest rc $?"
    python3 bench/bench_user_cli.py --families fabric_1 --episodes 64 --extra "--workers 8" --tag h100-s6-fabric-w8 \
        --timeout 120 2>&1 | tail -4
    cp bench/results/user-cli-h100-s6-fabric-w8.json $OUT/ ;;
B)  # the plain CLI per family with the defaults
    python3 bench/bench_user_cli.py --tag h100-s6 --timeout 200 "${@:2}" 2>&1 | tee $OUT/user-cli-h100-s6.log | tail -12
    cp bench/results/user-cli-h100-s6.json $OUT/ ;;
D)  # cnt_pdms alone (the plain CLI, 4096 episodes) after the transduction chain, then pytest -m gpu
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s6 2>&1 | tee $OUT/transduction-h100-s6.log
    cp bench/results/transduction-h100-s6.json $OUT/
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 4096 --tag h100-s6-cnt --timeout 280 2>&1 | tee $OUT/user-cli-h100-s6-cnt.log | tail -6
    cp bench/results/user-cli-h100-s6-cnt.json $OUT/
    timeout 200 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s6.log | tail -8
    echo "pytest rc $?" | tee -a $OUT/pytest-gpu-h100-s6.log ;;
E)  # cnt_pdms with the kernel cache warm (as run: the 4096 run alone, right after D on the same machine)
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 64 --tag h100-s6-cnt-first64 --timeout 250 2>&1 | tail -4
    cp bench/results/user-cli-h100-s6-cnt-first64.json $OUT/
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 4096 --tag h100-s6-cnt --timeout 250 2>&1 | tee $OUT/user-cli-h100-s6-cnt.log | tail -6
    cp bench/results/user-cli-h100-s6-cnt.json $OUT/ ;;
C)  # the final round in one call: transduction chain, the plain CLI per family, then pytest -m gpu
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s6 2>&1 | tee $OUT/transduction-h100-s6.log
    cp bench/results/transduction-h100-s6.json $OUT/
    python3 bench/bench_user_cli.py --tag h100-s6 --timeout 200 2>&1 | tee $OUT/user-cli-h100-s6.log | tail -12
    cp bench/results/user-cli-h100-s6.json $OUT/
    timeout 240 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s6.log | tail -15
    echo "pytest rc $?" | tee -a $OUT/pytest-gpu-h100-s6.log ;;
F)  # shards handed on as packed (SLICES_PER_LENGTH): cnt_pdms warm-up (compiles the kernels), the 4096 run warm,
    # then the compact 6 x 6 mixed-frequency e2e bench as in session 5 (-s5-mix)
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 64 --tag h100-s6-cnt-first64-handon --timeout 200 2>&1 | tail -3
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 4096 --tag h100-s6-cnt-handon --timeout 160 2>&1 | tee $OUT/user-cli-h100-s6-cnt-handon.log | tail -4
    cp bench/results/user-cli-h100-s6-cnt-handon.json $OUT/
    timeout 230 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s6-mix 2>&1 | tee $OUT/gpu-pipeline-h100-s6-mix.log | tail -4
    cp bench/results/gpu-pipeline-h100-s6-mix.json $OUT/ ;;
esac
