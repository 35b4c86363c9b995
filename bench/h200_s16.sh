#!/usr/bin/env bash
# The device calls of session 16 (issue 16), run from the worktree copy on the H200 machine with the packages
# unpacked in /root/site: `bash bench/h200_s16.sh P|...`. Logs and result files go to $OUT as one tar per mode.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm, repack, prof
case "$1" in
P)  # ntype 8192: where the driver's "simulate" (press_stroke on MuJoCo Warp, in the driver) spends its time, with the
    # feed's ramp (batches of 2048, 4096, 2048) and without (one batch of 8192)
    warm ntype
    prof ntype-ramp2 -- generate ntype -o /tmp/prof-out --episodes 8192
    prof ntype-ramp0 simulate.generation.feed.RAMP_BATCHES=0 -- generate ntype -o /tmp/prof-out --episodes 8192
    prof ntype-ramp2-b -- generate ntype -o /tmp/prof-out --episodes 8192
    pack P ;;
esac
case "$1" in
Q)  # ntype's plain CLI with full driver batches and its worlds freed early (then stepping nothing alone: its physics
    # is the driver's); the pack's cost per byte into fresh, populated and reused shared blocks on this host
    warm ntype
    cli ntype 8192 h200-s16-ntype-b noalone
    timeout 200 python3 bench/bench_pack_copy.py --gb 8 --out $OUT/r/pack-copy-h200-s16.json 2>&1 | tee $OUT/r/logs/pack-copy-h200-s16.log
    pack Q ;;
esac
case "$1" in
R)  # the first batch's pack blocks populated ahead (feed.BlockPool.populate_ahead): velostat with it (then stepping
    # alone) and without (PIEZOTWIN_POPULATE_AHEAD=0) on one machine, then cnt_pdms and fabric_1 (then stepping alone)
    # with it; each family after a 256-episode warm-up run; one tar per step (a limit cuts only the last)
    warm velostat
    cli velostat 8192 h200-s16-velostat-pop; repack R1
    PIEZOTWIN_POPULATE_AHEAD=0 cli velostat 8192 h200-s16-velostat-nopop noalone; repack R2
    warm cnt_pdms
    cli cnt_pdms 4096 h200-s16-cnt_pdms-pop noalone; repack R3
    warm fabric_1
    cli fabric_1 8192 h200-s16-fabric_1-pop; pack R4 ;;
esac
