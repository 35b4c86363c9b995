#!/usr/bin/env bash
# The device calls of session 27 (issue 16), one H200: `bash bench/h200_s27.sh H`. Logs and result files go to $OUT.
# H: velostat 16384 as typed with the writers taking the feed's zero-block flags (Channel.nonzero_blocks, the
#    default) against PIEZOTWIN_BLOCK_HINTS=0 (scanned, as before), alternated in one call, stepping alone once.
# C: cnt_pdms 8192 as typed, flags against none, alternated (its shear field is sent as blocks).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
H)  warm velostat
    cli velostat 16384 h200-s27-velostat-hints-a
    PIEZOTWIN_BLOCK_HINTS=0 cli velostat 16384 h200-s27-velostat-scan-a noalone
    cli velostat 16384 h200-s27-velostat-hints-b noalone
    PIEZOTWIN_BLOCK_HINTS=0 cli velostat 16384 h200-s27-velostat-scan-b noalone
    pack H ;;
C)  warm cnt_pdms
    cli cnt_pdms 8192 h200-s27-cnt_pdms-hints-a noalone
    PIEZOTWIN_BLOCK_HINTS=0 cli cnt_pdms 8192 h200-s27-cnt_pdms-scan-a noalone
    cli cnt_pdms 8192 h200-s27-cnt_pdms-hints-b noalone
    PIEZOTWIN_BLOCK_HINTS=0 cli cnt_pdms 8192 h200-s27-cnt_pdms-scan-b noalone
    pack C ;;
esac
# P: velostat 16384 as typed with its driver under cProfile (what the sensor stage spends, now that the writers take
#    the flags), after a warm-up run.
if [ "$1" = P ]; then
    warm velostat
    prof velostat-h200-s27 -- generate velostat -o /tmp/prof-out --episodes 16384
    cp $OUT/r/logs/profile-velostat-h200-s27.txt $OUT/ 2>/dev/null
    pack P
fi
# U: velostat 16384 as typed with the calibration unit index made on the device (the host's numpy pass over the
#    centroids waited on the interpreter the feed's threads hold), twice (stepping alone with the first), then its
#    driver under cProfile again.
if [ "$1" = U ]; then
    warm velostat
    cli velostat 16384 h200-s27-velostat-unit-a
    cli velostat 16384 h200-s27-velostat-unit-b noalone
    prof velostat-unit-h200-s27 -- generate velostat -o /tmp/prof-out --episodes 16384
    cp $OUT/r/logs/profile-velostat-unit-h200-s27.txt $OUT/ 2>/dev/null
    pack U
fi
