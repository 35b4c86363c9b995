#!/usr/bin/env bash
# The device calls of session 25 (issue 16), one H200: `bash bench/h200_s25.sh A`. Logs and result files go to $OUT.
# The change: the GPU feed's taxel fields leave the device as their non-zero taxel blocks (simulate/contact/
# field_blocks.py); PIEZOTWIN_FIELD_BLOCKS=0 sends them whole, as before.
# A: velostat 16384 as typed with blocks (and stepping alone), whole, with blocks again: one call, in that order.
# B: cnt_pdms 8192 as typed (its shear field is all zero on a normal press, its other fields loaded on most blocks):
#    with blocks, whole, with blocks again, one call.
# D: velostat 16384 as typed with blocks, its driver under cProfile (bench/profile_cli.py).
# N: ntype 24576 as typed, with its contact stage stepped alone (bench_mjw_alone.py now steps press_stroke's worlds:
#    protocols + MuJoCo Warp worlds with the stick-slip kernel, per feed batch).
# P: ntype 24576 with its worlds in the physics processes (the default now; with stepping alone), then in the driver
#    (PIEZOTWIN_STAGES_IN_DRIVER=1, as before), one call.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
A)  warm velostat
    cli velostat 16384 h200-s25-velostat-blocks1
    PIEZOTWIN_FIELD_BLOCKS=0 cli velostat 16384 h200-s25-velostat-whole noalone
    cli velostat 16384 h200-s25-velostat-blocks2 noalone
    pack A ;;
B)  warm cnt_pdms
    cli cnt_pdms 8192 h200-s25-cnt_pdms-blocks1 noalone
    PIEZOTWIN_FIELD_BLOCKS=0 cli cnt_pdms 8192 h200-s25-cnt_pdms-whole noalone
    cli cnt_pdms 8192 h200-s25-cnt_pdms-blocks2 noalone
    pack B ;;
N)  warm ntype
    cli ntype 24576 h200-s25-ntype
    pack N ;;
P)  warm ntype
    cli ntype 24576 h200-s25-ntype-processes
    PIEZOTWIN_STAGES_IN_DRIVER=1 cli ntype 24576 h200-s25-ntype-driver noalone
    pack P ;;
D)  warm velostat
    prof velostat-h200-s25 -- generate velostat -o /tmp/prof-out --episodes 16384
    pack D ;;
esac
