#!/usr/bin/env bash
# The device calls of session 18 (issue 16), run from the worktree copy on the H200 machine with the packages
# unpacked in /root/site: `bash bench/h200_s18.sh A|B|C|D|E` (B was not run: D measured cnt_pdms with the final
# layout). Logs and result files go to $OUT as one tar per step.
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack, warm, repack, prof
whole() {  # every chunk written, zeros too (the code before this session)
    export PIEZOTWIN_SKIP_ZERO_CHUNKS=0; cli "$@"; unset PIEZOTWIN_SKIP_ZERO_CHUNKS
}
case "$1" in
A)  # all-zero chunks left unwritten (velostat's shear field, 48 % of its bytes): the plain CLI for velostat 8192,
    # with and without, two pairs in both orders after a warm-up run, then MuJoCo Warp stepping the same worlds alone
    warm velostat
    cli velostat 8192 h200-s18-velostat noalone; repack A1
    whole velostat 8192 h200-s18-velostat-whole noalone; repack A2
    whole velostat 8192 h200-s18-velostat-whole2 noalone; repack A3
    cli velostat 8192 h200-s18-velostat-2; pack A4 ;;
B)  # the same for cnt_pdms 4096 (shear 33 % of its bytes; writer-bound: 28 % of the disk's raw speed)
    warm cnt_pdms
    cli cnt_pdms 4096 h200-s18-cnt_pdms noalone; repack B1
    whole cnt_pdms 4096 h200-s18-cnt_pdms-whole noalone; repack B2
    whole cnt_pdms 4096 h200-s18-cnt_pdms-whole2 noalone; repack B3
    cli cnt_pdms 4096 h200-s18-cnt_pdms-2 noalone; pack B4 ;;
esac
case "$1" in
C)  # which taxel-field chunks are all zero on the GPU path (velostat 512 and cnt_pdms 256 episodes, plain CLI)
    for f in velostat:512 cnt_pdms:256; do
        fam=${f%%:*}; n=${f##*:}; rm -rf /tmp/z-$fam
        timeout 250 python3 -m piezotwin generate $fam -o /tmp/z-$fam --episodes $n 2>&1 | grep -v "^Module" | grep -E "engine|samples/s" | cut -c1-200
        python3 bench/gpu_zero_fields.py /tmp/z-$fam --out $OUT/r/gpu-zero-fields-h200-s18-$fam.json
    done; pack C ;;
esac
frames() {  # whole frames per chunk (the layout before the taxel blocks); all-zero chunks still unwritten
    export PIEZOTWIN_TAXEL_BLOCK=0; cli "$@"; unset PIEZOTWIN_TAXEL_BLOCK
}
case "$1" in
D)  # taxel fields in blocks of 16 taxels (the blocks a press never reaches stay zero, unwritten): velostat 8192, two
    # pairs in both orders after a warm-up run; cnt_pdms 4096 (its punch covers the pad: no zero blocks) one pair
    warm velostat
    cli velostat 8192 h200-s18-velostat-blocks noalone; repack D1
    frames velostat 8192 h200-s18-velostat-frames noalone; repack D2
    frames velostat 8192 h200-s18-velostat-frames2 noalone; repack D3
    cli velostat 8192 h200-s18-velostat-blocks2 noalone; repack D4
    warm cnt_pdms
    cli cnt_pdms 4096 h200-s18-cnt_pdms-blocks noalone; repack D5
    frames cnt_pdms 4096 h200-s18-cnt_pdms-frames noalone; pack D6 ;;
esac
case "$1" in
E)  # the session's final code as a user types it (README table): velostat 8192 with MuJoCo Warp stepping alone,
    # cnt_pdms 4096; and two GPU-made velostat shards brought back to price the writers on GPU data locally
    warm velostat
    cli velostat 8192 h200-s18-velostat-final; repack E1
    rm -rf /tmp/g && python3 -m piezotwin generate velostat -o /tmp/g --episodes 24 > /dev/null 2>&1
    mkdir -p $OUT/r/shards && cp $(find /tmp/g -name "*.h5" | sort | head -2) $OUT/r/shards/; repack E2
    warm cnt_pdms
    cli cnt_pdms 4096 h200-s18-cnt_pdms-final noalone; pack E3 ;;
esac
