#!/usr/bin/env bash
# The device calls of session 19 (issue 16): MuJoCo Warp's time chunks two in flight (`WarpWorlds.run`: the
# device steps one chunk while the host takes the other's sensors and makes the next one's controls) against
# session 18's last code (8d0f09c: one chunk at a time, unpacked in /tmp/old), new and old on the same machine:
# `bash bench/h200_s19.sh T|A|D|E|B|C|F`, in that order (T, A and D ran the first design, see bench/README.md;
# D on a second machine, E, B, C and F on a third). Logs and result files go to $OUT as one tar per step.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm, repack
mkdir -p /tmp/old && tar xzf .device/ab/old-8d0f09c.tgz -C /tmp/old
alone() {  # family, episodes, tag: MuJoCo Warp stepping the CLI's worlds alone (this code)
    timeout 250 python3 bench/bench_mjw_alone.py --family $1 --episodes $2 --tag $3 --out $OUT/r 2>&1 \
        | grep -v "^Module" | tee $OUT/r/logs/alone-$3.log | tail -2
}
old_alone() {  # the same with session 18's code
    (cd /tmp/old && timeout 250 python3 bench/bench_mjw_alone.py --family $1 --episodes $2 --tag $3 --out $OUT/r 2>&1 \
        | grep -v "^Module" | tee $OUT/r/logs/alone-$3.log | tail -2)
}
old_cli() {  # the plain CLI with session 18's code
    (cd /tmp/old && python3 bench/bench_user_cli.py --families $1 --episodes $2 --tag $3 --timeout 280 --out $OUT/r 2>&1 \
        | tee $OUT/r/logs/user-cli-$3.log | tail -2)
}
case "$1" in
T)  # the CUDA tests of the contact stage (the chunks in flight give the one-chunk values), compiling the kernels
    timeout 400 python3 -m pytest tests/test_contact_mjw.py tests/test_contact_mjw_force.py -q -m gpu -p no:cacheprovider \
        2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-mjw-h200-s19.log | tail -4
    pack T ;;
A)  # velostat 8192: stepping alone new / old / new / old after a warm-up run, then the plain CLI new / old
    warm velostat
    alone velostat 8192 h200-s19-velostat-alone-new1; old_alone velostat 8192 h200-s19-velostat-alone-old1
    alone velostat 8192 h200-s19-velostat-alone-new2; old_alone velostat 8192 h200-s19-velostat-alone-old2
    repack A1
    cli velostat 8192 h200-s19-velostat noalone; old_cli velostat 8192 h200-s19-velostat-old; pack A2 ;;
B)  # fabric_1 8192: warm-up, stepping alone new / old, the plain CLI new (an old stepping alone, -old0, ran on the
    # same machine just before, from a mistyped call that ran only that step)
    warm fabric_1
    alone fabric_1 8192 h200-s19-fabric_1-alone-new1; old_alone fabric_1 8192 h200-s19-fabric_1-alone-old1; repack B1
    cli fabric_1 8192 h200-s19-fabric_1 noalone; pack B2 ;;
C)  # fabric_1 8192: the plain CLI old
    old_cli fabric_1 8192 h200-s19-fabric_1-old; pack C ;;
F)  # the session's final code as a user types it (README table): velostat 8192 with MuJoCo Warp stepping alone
    warm velostat
    cli velostat 8192 h200-s19-velostat-final; pack F ;;
esac
case "$1" in
D)  # velostat stepping alone: which part of the chunks in flight was slower (old 16.6 s against new 22.8 s in A;
    # run with the knobs PIEZOTWIN_PIPELINE_SETS / _SYNC of commit "diagnostic knobs", since removed)
    alone velostat 8192 h200-s19-velostat-alone-new3
    PIEZOTWIN_PIPELINE_SETS=1 alone velostat 8192 h200-s19-velostat-alone-sets1
    PIEZOTWIN_PIPELINE_SYNC=1 alone velostat 8192 h200-s19-velostat-alone-sync
    old_alone velostat 8192 h200-s19-velostat-alone-old3; pack D ;;
E)  # the controls made by the helper thread (this thread only queues work): velostat alone new / old / new / old
    alone velostat 8192 h200-s19-velostat-alone-e-new1; old_alone velostat 8192 h200-s19-velostat-alone-e-old1
    alone velostat 8192 h200-s19-velostat-alone-e-new2; old_alone velostat 8192 h200-s19-velostat-alone-e-old2
    timeout 200 python3 -m pytest tests/test_contact_mjw.py -q -m gpu -p no:cacheprovider -k chunks \
        2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-chunks-h200-s19.log | tail -2
    pack E ;;
esac
