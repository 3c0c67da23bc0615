#!/usr/bin/env bash
# The checks only an accelerator can make, in one bounded run (each stage under its own time
# limit; a stage that fails or runs out is reported and the next one still runs):
#   1. the devices JAX sees;
#   2. the test suite without the slow tests, on the accelerator (one line per test);
#   3. close() right after dispatching a compiled scan over env.xla(): asynchronous dispatch is
#      real there, so the test is run once as committed and once with close()'s wait for the
#      queued steps taken out (the second must fail, or the test proves nothing there);
#   4. the JAX-side stages at large batches, where PPO's training time goes (both torsos), and
#      lax.scan over env.xla() against the Python loop.
#
#     bash benchmarks/gpu_check.sh OUT_DIR [PARALLEL_TESTS]
#
# SECONDS_LEFT (default 540) bounds the whole run: a stage gets its own limit or what is left,
# whichever is less, and none starts with under 20 s left.  TESTS (default: the whole suite)
# names the tests of stage 2.
# Writes OUT_DIR/check.log (every stage's log, in order) and OUT_DIR/results.tgz (the
# benchmarks' JSON, tables and plots).  Run from the repository root, with stori_jax and its
# dependencies importable by $PYTHON (default python3).
set -u
out=${1:?usage: gpu_check.sh OUT_DIR [PARALLEL_TESTS]}
parallel=${2:-$(( $(nproc) > 2 ? $(nproc) - 2 : 1 ))}
py=${PYTHON:-python3}
mkdir -p "$out/bench"
log="$out/check.log"
deadline=$(( $(date +%s) + ${SECONDS_LEFT:-540} ))
export XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1

stage() {  # stage NAME SECONDS COMMAND...: run it with a limit, its output into the log
    local name=$1 limit=$2 start rc
    shift 2
    start=$(date +%s)
    (( limit > deadline - start )) && limit=$(( deadline - start ))
    if (( limit < 20 )); then
        echo "===== $name: not run, the run's time is up" | tee -a "$log"
        return
    fi
    echo "===== $name (limit ${limit} s): $*" >>"$log"
    timeout -k 10 "$limit" "$@" >>"$log" 2>&1
    rc=$?
    echo "===== $name: exit $rc after $(( $(date +%s) - start )) s" | tee -a "$log"
}

close_test="tests/test_env_xla.py::test_close_right_after_dispatching_a_scan_lets_its_queued_steps_finish"
barrier="            jax.effects_barrier()  # xla steps still queued finish first"

stage devices 60 "$py" -c "import jax, jaxlib; print(jax.__version__, jaxlib.__version__, jax.devices())"
stage close-after-dispatch 60 "$py" -m pytest -q -p no:cacheprovider "$close_test"
if grep -qF "$barrier" stori_jax/env.py; then
    cp stori_jax/env.py "$out/env.py.orig"
    sed -i "s/^$barrier\$/            pass  # close() without its wait (the check's mutation)/" stori_jax/env.py
    stage close-after-dispatch-without-the-wait 60 "$py" -m pytest -q -p no:cacheprovider "$close_test"
    cp "$out/env.py.orig" stori_jax/env.py && rm "$out/env.py.orig"
else
    echo "===== close()'s wait is not where this script expects it: mutation stage skipped" | tee -a "$log"
fi
stage jax-stages 90 "$py" benchmarks/jax_stages.py --sizes 32 256 1024 --out "$out/bench"
stage ppo-rollout-nips 90 "$py" benchmarks/ppo_rollout.py --network nips --repeats 2 --out "$out/bench"
stage ppo-rollout-nature 90 "$py" benchmarks/ppo_rollout.py --network nature --repeats 2 --out "$out/bench"
stage xla-rollout 60 "$py" benchmarks/xla_rollout.py --sizes 8 32 --repeats 2 --out "$out/bench"
stage tests 300 "$py" -m pytest -v -p no:cacheprovider -m "not slow" -n "$parallel" --timeout 150 ${TESTS:-}
grep -E "FAILED|ERROR" "$log" | grep -v "^=====" | sort -u | head -40 | sed 's/^/failed: /' | tee -a "$log"
tar czf "$out/results.tgz" -C "$out" bench && rm -r "$out/bench"
