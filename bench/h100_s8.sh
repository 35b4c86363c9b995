#!/usr/bin/env bash
# The device calls of session 8 (issue 16: every family's default protocol on MuJoCo Warp), run from the worktree
# copy on the H100 machine with the packages unpacked in /root/site: `bash bench/h100_s8.sh A|FV|NC`. Logs and
# result files go to $OUT.
export PYTHONPATH=/root/site:. PYTHONUNBUFFERED=1 OMP_NUM_THREADS=4
set -o pipefail
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv,noheader
mkdir -p $OUT/logs
cli() {  # family, episodes, tag: the plain CLI, then MuJoCo Warp stepping the same worlds alone (merged into its file)
    python3 bench/bench_user_cli.py --families $1 --episodes $2 --tag $3 --timeout 280 2>&1 | tee $OUT/logs/user-cli-$3.log | tail -4
    if [ "$4" != "noalone" ]; then
        timeout 200 python3 bench/bench_mjw_alone.py --family $1 --episodes $2 --tag $3 2>&1 | grep -v "^Module" | tee -a $OUT/logs/user-cli-$3.log | tail -3
    fi
    cp bench/results/user-cli-$3.json $OUT/
}
case "$1" in
A)  # pytest -m gpu on the final code (compiles MuJoCo Warp's kernels for every family's scene: the CLI runs after are warm)
    timeout ${2:-480} python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/logs/pytest-gpu-h100-s8.log | tail -12
    echo "pytest rc $?" | tee -a $OUT/logs/pytest-gpu-h100-s8.log ;;
FV) # the plain CLI: fabric_1 (staircases, 5 ms), velostat (mix, 5 ms on the GPU path), each with MuJoCo Warp alone
    cli fabric_1 ${2:-8192} h100-s8-fabric
    cli velostat ${3:-16384} h100-s8-velostat ;;
NC) # the plain CLI: ntype (press_stroke: the stage runs in the driver, no separate physics), cnt_pdms again
    cli ntype ${2:-8192} h100-s8-ntype noalone
    cli cnt_pdms ${3:-4096} h100-s8-cnt ;;
L)  # final code (the GPU feed keeps lzf for the narrow-frame families): kernels of fabric / velostat compiled by
    # their CUDA tests, then the plain CLI of both again with MuJoCo Warp alone
    timeout 200 python3 -m pytest -q -m gpu -p no:cacheprovider tests/test_contact_mjw_force.py 2>&1 | tail -2
    cli fabric_1 ${2:-8192} h100-s8-fabric-lzf ;;
L2) cli velostat ${2:-8192} h100-s8-velostat-lzf
    timeout 300 python3 -m pytest -q -m gpu -p no:cacheprovider 2>&1 | grep -v "^Module" | tee $OUT/logs/pytest-gpu-h100-s8-final.log | tail -3
    echo "pytest rc $?" | tee -a $OUT/logs/pytest-gpu-h100-s8-final.log ;;
esac
