#!/usr/bin/env bash
# The device calls of session 7 (issue 16), run from the worktree copy on the H100 machine with the packages
# unpacked in /root/site: `bash bench/h100_s7.sh A|B|C|D`. Logs and result files go to $OUT.
export PYTHONPATH=/root/site:. PYTHONUNBUFFERED=1 OMP_NUM_THREADS=4
set -o pipefail
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv,noheader
case "$1" in
A)  # the transduction chain with the fused pad sum (prefetch depths 0/1/2/4), then pytest -m gpu
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s7 2>&1 | tee $OUT/transduction-h100-s7.log
    cp bench/results/transduction-h100-s7.json $OUT/
    timeout 300 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s7.log | tail -15
    echo "pytest rc $?" | tee -a $OUT/pytest-gpu-h100-s7.log ;;
B)  # compact 6 x 6, mixed 0.1-2 Hz, as -s5-mix / -s6-mix: the feed's default batch plan, then without the ramp
    timeout 280 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s7-mix 2>&1 | tee $OUT/gpu-pipeline-h100-s7-mix.log | tail -3
    cp bench/results/gpu-pipeline-h100-s7-mix.json $OUT/
    timeout 280 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --ramp-batches 0 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s7-mix-noramp 2>&1 | tee $OUT/gpu-pipeline-h100-s7-mix-noramp.log | tail -3
    cp bench/results/gpu-pipeline-h100-s7-mix-noramp.json $OUT/ ;;
C)  # the plain CLI, cnt_pdms 4096 episodes (kernel cache warmed by a 64-episode run first, as -s6-cnt-handon)
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 64 --tag h100-s7-cnt-first64 --timeout 250 2>&1 | tail -3
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 4096 --tag h100-s7-cnt --timeout 200 2>&1 | tee $OUT/user-cli-h100-s7-cnt.log | tail -4
    cp bench/results/user-cli-h100-s7-cnt.json $OUT/ ;;
D)  # a mix e2e with "$2" extra bench args and tag suffix "$3", then pytest -m gpu on the final code
    timeout 280 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 $2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s7-mix$3 2>&1 | tee $OUT/gpu-pipeline-h100-s7-mix$3.log | tail -3
    cp bench/results/gpu-pipeline-h100-s7-mix$3.json $OUT/
    timeout 250 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s7-final.log | tail -8
    echo "pytest rc $?" | tee -a $OUT/pytest-gpu-h100-s7-final.log ;;
R)  # registers / spills of the taxel kernels, then the transduction chain again (the kernel as now)
    python3 bench/kernel_resources.py --out $OUT/kernel-resources-h100-s7.json 2>&1 | tee $OUT/kernel-resources-h100-s7.log
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s7 2>&1 | tee $OUT/transduction-h100-s7.log | tail -4
    cp bench/results/transduction-h100-s7.json $OUT/ ;;
V)  # variants of the fused kernel: where its per-taxel stores lose time
    python3 bench/fused_variants.py --out $OUT/fused-variants-h100-s7.json 2>&1 | tee $OUT/fused-variants-h100-s7.log ;;
T)  # the fused kernel's variants, then the transduction chain (kernel and memory pool as now)
    python3 bench/fused_variants.py --out $OUT/fused-variants-h100-s7.json 2>&1 | tee $OUT/fused-variants-h100-s7.log
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s7 2>&1 | tee $OUT/transduction-h100-s7.log | tail -4
    cp bench/results/transduction-h100-s7.json $OUT/ ;;
M)  # what a fresh device array costs, then the transduction chain (fused outputs in reused buffers)
    python3 bench/alloc_cost.py --out $OUT/alloc-cost-h100-s7.json 2>&1 | tee $OUT/alloc-cost-h100-s7.log
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s7 2>&1 | tee $OUT/transduction-h100-s7.log | tail -4
    cp bench/results/transduction-h100-s7.json $OUT/ ;;
F1) # final code: the transduction chain, then pytest -m gpu
    python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s7 2>&1 | tee $OUT/transduction-h100-s7.log | tail -4
    cp bench/results/transduction-h100-s7.json $OUT/
    timeout 300 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s7.log | tail -8
    echo "pytest rc $?" | tee -a $OUT/pytest-gpu-h100-s7.log ;;
F2) # final code: the plain CLI, cnt_pdms (64 episodes to compile the kernels, then 4096 warm)
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 64 --tag h100-s7-cnt-first64 --timeout 250 2>&1 | tail -2
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 4096 --tag h100-s7-cnt --timeout 250 2>&1 | tee $OUT/user-cli-h100-s7-cnt.log | tail -4
    cp bench/results/user-cli-h100-s7-cnt.json bench/results/user-cli-h100-s7-cnt-first64.json $OUT/ ;;
F3) # final code: compact 6 x 6 mixed 0.1-2 Hz end to end (as -s6-mix)
    timeout 290 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h100-s7-mix-final 2>&1 | tee $OUT/gpu-pipeline-h100-s7-mix-final.log | tail -3
    cp bench/results/gpu-pipeline-h100-s7-mix-final.json $OUT/ ;;
P)  # final code (prefetch 1): pytest -m gpu, then the plain CLI cnt_pdms again (run-to-run spread of F2)
    timeout 300 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | tee $OUT/pytest-gpu-h100-s7-final.log | tail -8
    echo "pytest rc $?" | tee -a $OUT/pytest-gpu-h100-s7-final.log
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 64 --tag h100-s7-cnt-first64 --timeout 200 2>&1 | tail -1
    python3 bench/bench_user_cli.py --families cnt_pdms --episodes 4096 --tag h100-s7-cnt-b --timeout 200 2>&1 | tee $OUT/user-cli-h100-s7-cnt-b.log | tail -4
    cp bench/results/user-cli-h100-s7-cnt-b.json $OUT/ ;;
esac
