#!/usr/bin/env bash
# The device calls of session 23 (issue 16), one H200: `bash bench/h200_s23.sh A`. Logs and result files go to $OUT.
# A: cnt_pdms 8192 as typed, now that the physics processes step in turns (session 22 measured it before), then
#    stepping alone; velostat 16384 stepped alone in one batch of 16384 worlds (the default plan: a ramp batch of
#    8192, then 8192) and the plain CLI without the ramp (PIEZOTWIN_RAMP_BATCHES=0: one batch), against
#    user-cli-h200-s22-velostat-turns.json (the default plan, 54.2 s).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
A)  warm cnt_pdms; cli cnt_pdms 8192 h200-s23-cnt_pdms
    warm velostat
    timeout 200 python3 bench/bench_mjw_alone.py --family velostat --episodes 16384 --worlds 16384 \
        --tag h200-s23-velostat-one-batch 2>&1 | grep -v "^Module" | tee $OUT/r/logs/mjw-alone-h200-s23-velostat-one-batch.log | tail -3
    cp bench/results/mjw-alone-h200-s23-velostat-one-batch*.json $OUT/r/ 2>/dev/null
    PIEZOTWIN_RAMP_BATCHES=0 cli velostat 16384 h200-s23-velostat-noramp noalone
    pack A ;;
B)  # cnt_pdms 8192 as typed, the GPU turns off (side by side, as before session 22) then on, back to back in one
    # call (A's run with turns took 56.4 s against session 22's 50.2 s without, in another call whose disk wrote
    # 13 % slower)
    warm cnt_pdms
    PIEZOTWIN_GPU_TURNS=0 cli cnt_pdms 8192 h200-s23-cnt_pdms-sidebyside noalone
    cli cnt_pdms 8192 h200-s23-cnt_pdms-turns noalone
    pack B ;;
C)  # cnt_pdms 8192 in turns, the feed populating its first batch's blocks through that batch's pack
    # (PIEZOTWIN_POPULATE_THROUGH=1) or stopping when the batch is back (0, the default then), alternated in one call
    warm cnt_pdms
    PIEZOTWIN_POPULATE_THROUGH=1 cli cnt_pdms 8192 h200-s23-cnt_pdms-through1 noalone
    cli cnt_pdms 8192 h200-s23-cnt_pdms-stop1 noalone
    PIEZOTWIN_POPULATE_THROUGH=1 cli cnt_pdms 8192 h200-s23-cnt_pdms-through2 noalone
    cli cnt_pdms 8192 h200-s23-cnt_pdms-stop2 noalone
    pack C ;;
D)  # velostat 16384 as typed on the code now (blocks populated through the first pack), then stepping alone
    warm velostat; cli velostat 16384 h200-s23-velostat
    pack D ;;
esac
