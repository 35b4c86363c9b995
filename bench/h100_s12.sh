#!/usr/bin/env bash
# The device calls of session 12 (issue 16: the plain CLI measured for every family with session 11's writers; the
# CLI's start-up and exit timed and cut; the transduction chain's GPU activities), run from the worktree copy on the
# H100 machine with the packages unpacked in /root/site: `bash bench/h100_s12.sh W|A|B|X|G|P|C|V|N|F [episodes]`.
# Mode A also runs the base commit's tree (the repository root, one level up) for the before / after of start-up.
# Logs and result files go to $OUT as one tar per mode (at most 8 files come back).
source "$(dirname "$0")/h100_lib.sh"  # environment, cli (plain CLI + MuJoCo Warp alone), pack
case "$1" in
W)  # a fresh machine: small runs compile MuJoCo Warp's and the sensors' kernels for each family (not timed)
    for f in cnt_pdms velostat ntype; do
        timeout 250 python3 bench/bench_user_cli.py --families $f --episodes 128 --tag warm-$f 2>&1 | grep -v "^Module" | tail -2 | cut -c1-400
    done
    pack W ;;
A)  # start-up and exit, before (the base tree: the repository root) / after (this tree), small runs, interleaved
    for i in $(seq ${2:-1}); do
        for f in ntype cnt_pdms; do
            n=64; [ $f = cnt_pdms ] && n=128
            (cd .. && PYTHONPATH=/root/site:. timeout 200 python3 bench/bench_user_cli.py --families $f --episodes $n \
                --tag h100-s12-startup-base-$f-$i 2>&1 | grep -v "^Module" | tail -2 | cut -c1-300; \
                cp bench/results/user-cli-h100-s12-startup-base-$f-$i.json $OUT/r/)
            timeout 200 python3 bench/bench_user_cli.py --families $f --episodes $n --tag h100-s12-startup-$f-$i 2>&1 \
                | grep -v "^Module" | tail -3 | cut -c1-600
            cp bench/results/user-cli-h100-s12-startup-$f-$i.json $OUT/r/
        done
    done
    pack A ;;
X)  # the transduction chain on CUDA, with the GPU time of each kernel and copy of one fused chain + readout
    timeout ${2:-200} python3 bench/bench_transduction.py --cuda-only --gpu-episodes 256 --tag h100-s12 2>&1 | grep -v "^Module" \
        | tee $OUT/r/logs/transduction-h100-s12.log | tail -6 | cut -c1-3000
    cp bench/results/transduction-h100-s12.json $OUT/r/
    pack X ;;
B)  # second machine: start-up and exit before / after on velostat (its physics in their own processes), warmed first
    timeout 200 python3 bench/bench_user_cli.py --families velostat --episodes 128 --tag warm-velostat 2>&1 | grep -v "^Module" | tail -1 | cut -c1-300
    for i in $(seq ${2:-1}); do
        (cd .. && PYTHONPATH=/root/site:. timeout 200 python3 bench/bench_user_cli.py --families velostat --episodes 128 \
            --tag h100-s12-startup-base-velostat-$i 2>&1 | grep -v "^Module" | tail -2 | cut -c1-300; \
            cp bench/results/user-cli-h100-s12-startup-base-velostat-$i.json $OUT/r/)
        timeout 200 python3 bench/bench_user_cli.py --families velostat --episodes 128 --tag h100-s12-startup-velostat-$i 2>&1 \
            | grep -v "^Module" | tail -3 | cut -c1-600
        cp bench/results/user-cli-h100-s12-startup-velostat-$i.json $OUT/r/
    done
    pack B ;;
G)  # the GPU tests of the fused kernel and the readout (four-step sums against one-step sums, bit for bit)
    timeout ${2:-300} python3 -m pytest tests/test_gpu.py -q -m gpu -p no:cacheprovider -k "fused or readout or full_chain" 2>&1 \
        | grep -v "^Module" | tee $OUT/r/logs/pytest-gpu-h100-s12.log | tail -6
    pack G ;;
P)  # cProfile of a 16-episode ntype run (main thread), top 45 by cumulative time (first machine, before the mujoco_warp cut)
    rm -rf /tmp/pds; timeout 120 python3 -m cProfile -o $OUT/r/cli.prof -m piezotwin.cli generate ntype -o /tmp/pds --episodes 16 > /dev/null 2>&1
    python3 -c "import pstats; pstats.Stats('$OUT/r/cli.prof').sort_stats('cumulative').print_stats(45)" 2>&1 | grep -v "^$" | cut -c1-200 | tail -48
    pack P ;;
C)  cli cnt_pdms ${2:-4096} h100-s12-cnt; pack C ;;
V)  cli velostat ${2:-8192} h100-s12-velostat; pack V ;;
N)  cli ntype ${2:-8192} h100-s12-ntype noalone; pack N ;;
F)  cli fabric_1 ${2:-8192} h100-s12-fabric; pack F ;;
esac
