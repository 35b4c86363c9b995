#!/usr/bin/env bash
# The device calls of session 22 (issue 16): every family's plain CLI with N chosen for about a minute, and the two
# bench configurations, on one H200 in one session, so that the README table shows one run's numbers:
# `bash bench/h200_s22.sh A|B|C`. Logs and result files go to $OUT as one tar per step.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
A)  # cnt_pdms (0.1-2 Hz mix, the default) and velostat as a user types them, each then stepping alone
    warm cnt_pdms; cli cnt_pdms 8192 h200-s22-cnt_pdms
    warm velostat; cli velostat 16384 h200-s22-velostat
    pack A ;;
B)  # the physics processes' GPU stepping in turns (the new default) against side by side (PIEZOTWIN_GPU_TURNS=0,
    # as in A): velostat 16384 both ways in turn, then stepping alone; then ntype (its own contact stage in the
    # driver: no stepping-alone run) and fabric_1
    warm velostat
    cli velostat 16384 h200-s22-velostat-turns noalone
    PIEZOTWIN_GPU_TURNS=0 cli velostat 16384 h200-s22-velostat-sidebyside
    warm ntype; cli ntype 24576 h200-s22-ntype noalone
    warm fabric_1; cli fabric_1 4096 h200-s22-fabric_1
    pack B ;;
C)  # the old single-frequency bench config (compact 6 x 6 at 0.5 Hz, 196608 episodes), then the mixed one
    timeout 250 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --tag h200-s22-single \
        2>&1 | grep -v "^Module" | tee $OUT/r/logs/gpu-pipeline-h200-s22-single.log | tail -2 | cut -c1-600
    cp bench/results/gpu-pipeline-h200-s22-single.json $OUT/r/
    timeout 300 python3 bench/bench_gpu_pipeline.py --parts e2e --workers 8 --shards-per-worker 2 --schedule length \
        --override "protocol.frequencies_hz=[0.1,0.5,1.0,2.0]" --tag h200-s22-mix 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/gpu-pipeline-h200-s22-mix.log | tail -2 | cut -c1-600
    cp bench/results/gpu-pipeline-h200-s22-mix.json $OUT/r/
    pack C ;;
esac
