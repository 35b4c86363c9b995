#!/usr/bin/env bash
# The device calls of session 20 (issue 16): session 19's last code (the chunk sets as the review left them, which
# ran on Warp's CPU device only) on CUDA, and a second machine's pair for fabric_1's plain CLI against MuJoCo Warp
# stepping alone: `bash bench/h200_s20.sh T|F|V`. Logs and result files go to $OUT as one tar per step.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm, repack
case "$1" in
T)  # the CUDA tests of the contact stages: the chunks in flight, the C MuJoCo equivalence, ntype's stick-slip worlds
    timeout 500 python3 -m pytest tests/test_contact_mjw.py tests/test_contact_mjw_force.py tests/test_press_stroke_mjw.py \
        -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-mjw-h200-s20.log | tail -4
    pack T ;;
F)  # fabric_1 8192 as a user types it, then MuJoCo Warp stepping the same worlds alone (second machine's pair)
    warm fabric_1
    cli fabric_1 8192 h200-s20-fabric_1; pack F ;;
V)  # velostat 8192 as a user types it, then stepping alone
    warm velostat
    cli velostat 8192 h200-s20-velostat; pack V ;;
esac
case "$1" in
R)  # the staging buffers page-locked while the first batch steps (`reserve_staging`): its CUDA test, then velostat
    # 8192 as a user types it with and without (PIEZOTWIN_RESERVE_STAGING=0), in turn
    timeout 200 python3 -m pytest tests/test_gpu.py -q -m gpu -p no:cacheprovider -k staging \
        2>&1 | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-staging-h200-s20.log | tail -2
    warm velostat
    cli velostat 8192 h200-s20-velostat-reserve1 noalone
    PIEZOTWIN_RESERVE_STAGING=0 cli velostat 8192 h200-s20-velostat-noreserve1 noalone
    cli velostat 8192 h200-s20-velostat-reserve2 noalone
    PIEZOTWIN_RESERVE_STAGING=0 cli velostat 8192 h200-s20-velostat-noreserve2 noalone
    pack R ;;
esac
case "$1" in
S)  # the float32 solver's lateral residual read as 0 (TANGENTIAL_RESIDUAL_SHARE): a small velostat dataset's zero
    # shares (bench/gpu_zero_fields.py; also compiles the kernels), then velostat 8192 and cnt_pdms 4096 as a user
    # types them (not run in session 20: no device time was left)
    timeout 200 python3 -m piezotwin generate velostat -o /tmp/z-velostat --episodes 256 2>&1 | tail -1 | cut -c1-200
    python3 bench/gpu_zero_fields.py /tmp/z-velostat --out $OUT/r/gpu-zero-fields-h200-s20-velostat.json | tail -3
    rm -rf /tmp/z-velostat
    cli velostat 8192 h200-s20-velostat-residual noalone
    warm cnt_pdms; cli cnt_pdms 4096 h200-s20-cnt_pdms-residual noalone; pack S ;;
esac
