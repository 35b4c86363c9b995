# Shared by the per-session device scripts (bench/h100_s9.sh ... bench/h200_s17.sh): the environment on the H100
# machine (packages unpacked in /root/site), the plain-CLI measurement and the packing of $OUT. Sourced, not run.
export PYTHONPATH=/root/site:. PYTHONUNBUFFERED=1 OMP_NUM_THREADS=4
set -o pipefail
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv,noheader
mkdir -p $OUT/r/logs
cli() {  # family, episodes, tag: the plain CLI, then MuJoCo Warp stepping the same worlds alone (merged into its file)
    python3 bench/bench_user_cli.py --families $1 --episodes $2 --tag $3 --timeout 280 2>&1 | tee $OUT/r/logs/user-cli-$3.log | tail -4
    if [ "$4" != "noalone" ]; then
        timeout 200 python3 bench/bench_mjw_alone.py --family $1 --episodes $2 --tag $3 2>&1 | grep -v "^Module" | tee -a $OUT/r/logs/user-cli-$3.log | tail -3
    fi
    cp bench/results/user-cli-$3.json $OUT/r/
}
pack() { tar czf $OUT/results-$1.tgz -C $OUT/r . ; rm -rf $OUT/r; }
warm() {  # a small run that compiles / loads the family's kernels (not timed)
    timeout 200 python3 bench/bench_user_cli.py --families $1 --episodes 256 --tag warm-$1 2>&1 | grep -v "^Module" | tail -1 | cut -c1-300
}
repack() { pack $1; mkdir -p $OUT/r/logs; }  # one tar per step, then go on
prof() {  # tag, [MODULE.NAME=VALUE ...] -- piezotwin args: the CLI's driver under cProfile
    local tag=$1; shift
    rm -rf /tmp/prof-out
    timeout 280 python3 bench/profile_cli.py $OUT/r/logs/profile-$tag.txt "$@" 2>&1 | grep -v "^Module" | tail -3
    rm -rf /tmp/prof-out
}
