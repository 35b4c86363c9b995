#!/usr/bin/env bash
# The device calls of session 24 (issue 16), one H200: `bash bench/h200_s24.sh A`. Logs and result files go to $OUT.
# A: the GPU path's physics step per protocol is now the largest that divides the sample period within the measured
#    limit (velostat kinds 100/13 = 7.69 ms, fabric staircases 100/19 = 5.26 ms; both 5 ms before; results/physics-
#    step-<family>.json): velostat 16384 and fabric_1 4096 as typed, each with stepping alone at the same step, and
#    velostat 16384 at the previous 5 ms (`--set sampling.physics_timestep_s=0.005`, as a user would set it) in the
#    same call.
# B: velostat 49152 (a run of several full batches) at the new step and at 5 ms, one call.
# C: fabric_1 4096 at 5.26 ms and at 5 ms, alternated twice in one call.
# D: velostat 16384 as typed, its driver under cProfile (bench/profile_cli.py).
# E: velostat 16384, the shards checked by their writers against by the driver too, one call: run on commit 366508b,
#    a probe reverted in the next commit (PIEZOTWIN_DRIVER_OPENS_SHARDS exists only there).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
A)  warm velostat; cli velostat 16384 h200-s24-velostat
    python3 bench/bench_user_cli.py --families velostat --episodes 16384 --tag h200-s24-velostat-5ms --timeout 280 \
        --extra "--set sampling.physics_timestep_s=0.005" 2>&1 | tee $OUT/r/logs/user-cli-h200-s24-velostat-5ms.log | tail -4
    cp bench/results/user-cli-h200-s24-velostat-5ms.json $OUT/r/
    warm fabric_1; cli fabric_1 4096 h200-s24-fabric_1
    pack A ;;
B)  # a longer run, where the stepping (not the tail) is the bound at 5 ms: velostat 49152 at the new default step and
    # at 5 ms, one call, in that order (no stepping alone)
    warm velostat; cli velostat 49152 h200-s24-velostat-49152 noalone
    python3 bench/bench_user_cli.py --families velostat --episodes 49152 --tag h200-s24-velostat-49152-5ms --timeout 290 \
        --extra "--set sampling.physics_timestep_s=0.005" 2>&1 | tee $OUT/r/logs/user-cli-h200-s24-velostat-49152-5ms.log | tail -4
    cp bench/results/user-cli-h200-s24-velostat-49152-5ms.json $OUT/r/
    pack B ;;
C)  # fabric_1 4096 at the new step (100/19 = 5.26 ms) and at 5 ms, alternated in one call (A ran the new step only)
    warm fabric_1
    cli fabric_1 4096 h200-s24-fabric_1-step1 noalone
    python3 bench/bench_user_cli.py --families fabric_1 --episodes 4096 --tag h200-s24-fabric_1-5ms1 --timeout 200 \
        --extra "--set sampling.physics_timestep_s=0.005" 2>&1 | tee $OUT/r/logs/user-cli-h200-s24-fabric_1-5ms1.log | tail -4
    cp bench/results/user-cli-h200-s24-fabric_1-5ms1.json $OUT/r/
    cli fabric_1 4096 h200-s24-fabric_1-step2 noalone
    python3 bench/bench_user_cli.py --families fabric_1 --episodes 4096 --tag h200-s24-fabric_1-5ms2 --timeout 200 \
        --extra "--set sampling.physics_timestep_s=0.005" 2>&1 | tee $OUT/r/logs/user-cli-h200-s24-fabric_1-5ms2.log | tail -4
    cp bench/results/user-cli-h200-s24-fabric_1-5ms2.json $OUT/r/
    pack C ;;
D)  # where the driver's time goes at the new step: velostat 16384 as typed under cProfile (the driver's main thread)
    warm velostat
    prof velostat-h200-s24 -- generate velostat -o /tmp/prof-out --episodes 16384
    pack D ;;
E)  # velostat 16384 as typed: the writers open their shards back (the default now) against the driver doing it too
    # (PIEZOTWIN_DRIVER_OPENS_SHARDS=1, as before), in that order, one call
    warm velostat
    cli velostat 16384 h200-s24-velostat-writercheck noalone
    PIEZOTWIN_DRIVER_OPENS_SHARDS=1 cli velostat 16384 h200-s24-velostat-drivercheck noalone
    pack E ;;
esac
