#!/usr/bin/env bash
# The device calls of session 15 (issue 16: the dataset summary merged into the manifest, no shard reopened; the
# feed's slices per length group as an A/B), run from the worktree copy on the H200 machine with the packages
# unpacked in /root/site: `bash bench/h200_s15.sh A|B|R|T|N`. Logs and result files go to $OUT as one tar per mode.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
A)  # fabric_1: warm-up, then the plain CLI (default slices) + stepping alone
    warm fabric_1
    cli fabric_1 8192 h200-s15-fabric; pack A ;;
B)  # fabric_1 with 8 slices per length group (no alone: A's machine), velostat and cnt_pdms with the defaults
    PIEZOTWIN_FEED_SLICES=8 cli fabric_1 8192 h200-s15-fabric-s8 noalone
    warm velostat
    cli velostat 8192 h200-s15-velostat
    warm cnt_pdms
    cli cnt_pdms 4096 h200-s15-cnt noalone
    pack B ;;
R)  # the staging buffers unpinned while the writers finish (exit after the last write was 1.6-1.7 s): velostat with
    # stepping alone, cnt_pdms; then the GPU test of release_staging
    warm velostat
    cli velostat 8192 h200-s15-velostat-rel
    warm cnt_pdms
    cli cnt_pdms 4096 h200-s15-cnt-rel noalone
    timeout 120 python3 -m pytest tests/test_gpu.py -q -m gpu -p no:cacheprovider -k release 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/pytest-gpu-release-h200-s15.log | tail -3
    pack R ;;
T)  # fabric_1 and velostat, each after a warm-up run, with stepping alone (session 15 ran this with the MJCF's
    # contact sensor trimmed, since reverted: -fabric-trim); `T cols` measures the recorded columns
    # (load_field.read_columns) against -fabric, -fabric-b and -velostat
    warm fabric_1
    cli fabric_1 8192 h200-s15-fabric-${2:-trim}
    warm velostat
    cli velostat 8192 h200-s15-velostat-${2:-trim}
    pack T ;;
N)  # every family's plain CLI as the README's rows measure them (fabric_1 and velostat with stepping alone), each
    # after a warm-up run, tagged h200-<$2>-<family>: the first GPU run of session 15's last changes (the read
    # columns, the physics processes started ahead); two calls (fabric_1 takes ~3.5 min with its alone run)
    for f in ${3:-fabric_1 velostat cnt_pdms ntype}; do
        warm $f
        case $f in
            fabric_1|velostat) cli $f 8192 h200-$2-$f ;;
            cnt_pdms) cli $f 4096 h200-$2-$f noalone ;;
            ntype) cli $f 8192 h200-$2-$f noalone ;;
        esac
    done
    pack N ;;
esac
