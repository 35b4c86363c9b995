#!/usr/bin/env bash
# The device calls of session 17 (issue 16), run from the worktree copy on the H200 machine with the packages
# unpacked in /root/site: `bash bench/h200_s17.sh A|...`. Logs and result files go to $OUT as one tar per step.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm, repack, prof
case "$1" in
A)  # where the driver's serial tail goes (its "simulate": load field, sensor chain, copies back; "pack"): the plain
    # CLI under cProfile for velostat 8192, fabric_1 8192 and cnt_pdms 4096, each after a 256-episode warm-up run
    warm velostat
    prof velostat-h200-s17 -- generate velostat -o /tmp/prof-out --episodes 8192; repack A1
    warm fabric_1
    prof fabric_1-h200-s17 -- generate fabric_1 -o /tmp/prof-out --episodes 8192; repack A2
    warm cnt_pdms
    prof cnt_pdms-h200-s17 -- generate cnt_pdms -o /tmp/prof-out --episodes 4096; pack A3 ;;
esac
case "$1" in
B)  # the driver's tail cut (pack copies in the driver's thread for small pieces and one task per pack thread for large
    # ones, the load channels' float32 cast over threads, the shard check reading one attribute): fabric_1 8192 and
    # velostat 8192, this code then session 16's last (c1bcb31, unpacked in /tmp/old) on one machine, each family
    # after a 256-episode warm-up run, then MuJoCo Warp stepping the same worlds alone
    mkdir -p /tmp/old && tar xzf .device/ab/old-c1bcb31.tgz -C /tmp/old
    old() { (cd /tmp/old && python3 bench/bench_user_cli.py --families $1 --episodes $2 --tag $3 --timeout 280 --out $OUT/r 2>&1 | tee $OUT/r/logs/user-cli-$3.log | tail -2); }
    warm fabric_1
    cli fabric_1 8192 h200-s17-fabric_1 noalone; repack B1
    old fabric_1 8192 h200-s17-fabric_1-old; repack B2
    timeout 200 python3 bench/bench_mjw_alone.py --family fabric_1 --episodes 8192 --tag h200-s17-fabric_1 2>&1 | grep -v "^Module" | tail -2
    cp bench/results/user-cli-h200-s17-fabric_1.json $OUT/r/; repack B3
    warm velostat
    cli velostat 8192 h200-s17-velostat; repack B4
    old velostat 8192 h200-s17-velostat-old; pack B5 ;;
esac
case "$1" in
D)  # the first batch's protocols made by the driver while the physics processes import: velostat 2048 after a warm-up
    warm velostat
    cli velostat 2048 h200-s17-velostat-2048-protos noalone; pack D ;;
esac
