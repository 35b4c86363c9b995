#!/usr/bin/env bash
# The device calls of session 26 (issue 16), one H200: `bash bench/h200_s26.sh R`. Logs and result files go to $OUT.
# R: ntype 24576 as typed with a ramp of smaller first batches (PIEZOTWIN_CONTACT_RAMP_BATCHES=2: 2048, 4096, then
#    full; its worlds now step in the physics processes, so a small first batch lets the driver and the writers start
#    while the next steps) against none (the default), alternated twice in one call; stepping alone once (its feed
#    batches, no ramp, as always).
# V: velostat 16384 as typed with stepping alone (the pack's estimate for block fields, session 25: first measured
#    on a GPU in W's runs, `--workers 12`, the default there), then fabric_1 4096 as typed with stepping alone.
# A: all four families as typed on one machine, each with stepping alone (cnt_pdms without: its bound is the disk),
#    so the README table holds one host's numbers.
# W: (run inline, see bench/README) ntype 24576 and velostat 16384 with --workers 14 against 12.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm
case "$1" in
R)  warm ntype
    cli ntype 24576 h200-s26-ntype-ramp0a
    PIEZOTWIN_CONTACT_RAMP_BATCHES=2 cli ntype 24576 h200-s26-ntype-ramp2a noalone
    cli ntype 24576 h200-s26-ntype-ramp0b noalone
    PIEZOTWIN_CONTACT_RAMP_BATCHES=2 cli ntype 24576 h200-s26-ntype-ramp2b noalone
    pack R ;;
R1) warm ntype
    PIEZOTWIN_CONTACT_RAMP_BATCHES=1 cli ntype 24576 h200-s26-ntype-ramp1a noalone
    cli ntype 24576 h200-s26-ntype-ramp0c noalone
    PIEZOTWIN_CONTACT_RAMP_BATCHES=1 cli ntype 24576 h200-s26-ntype-ramp1b noalone
    pack R1 ;;
V)  warm velostat
    cli velostat 16384 h200-s26-velostat
    warm fabric_1
    cli fabric_1 4096 h200-s26-fabric_1
    pack V ;;
A)  for f in velostat fabric_1 ntype cnt_pdms; do warm $f; done
    cli velostat 16384 h200-s26-all-velostat
    cli fabric_1 4096 h200-s26-all-fabric_1
    cli ntype 24576 h200-s26-all-ntype
    cli cnt_pdms 8192 h200-s26-all-cnt_pdms noalone
    pack A ;;
esac
