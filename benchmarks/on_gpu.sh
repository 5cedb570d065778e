#!/usr/bin/env bash
# The test suite on a GPU machine in one call, its log kept even when cut off:
#   bash benchmarks/on_gpu.sh [pytest args]   (log in $OUT/tests.log, else out/tests.log;
#   PYTHON, TEST_S (time limit, s), WORKERS and PER_TEST_S override python3, 420, 16 and 240)
# Each failure's reason is written to failures.log beside the log as it happens (a cut-off run
# keeps them); a test that outruns PER_TEST_S fails as "Timeout" (pytest-timeout, which the
# lent machines' image holds), so one slow test cannot eat the lease.
# Test-only packages the machine lacks (allantools, imucal, h5netcdf) travel as wheels in
# .whl/ (name .whl in the call's carry); without them those tests are skipped. Fetch them here:
#   echo /.whl/ >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#     --implementation cp --platform manylinux2014_x86_64 -d .whl \
#     allantools==2024.6 imucal==2.6.0 h5netcdf==1.8.2
# The benchmark beside it: python3 benchmarks/gpu_backend.py (≈ 3.5 min on an H200).
set -u
if ls .whl/*.whl > /dev/null 2>&1; then
  "${PYTHON:-python3}" -m pip install -q --no-index --no-deps --no-compile --upgrade --target /tmp/site .whl/*.whl \
    && export PYTHONPATH=/tmp/site:${PYTHONPATH:-}
fi
export PYTHONPATH=$PWD:${PYTHONPATH:-} PYTHONUNBUFFERED=1
export XLA_PYTHON_CLIENT_PREALLOCATE=false  # many workers share one GPU
export HRGJAX_TEST_FULL=${HRGJAX_TEST_FULL-1}  # the slow tier too (tests/conftest.py); 0: CI's tier
log=${OUT:-out}/tests.log
mkdir -p "$(dirname "$log")"
export HRGJAX_FAILURE_LOG=$(dirname "$log")/failures.log
timeout_arg=()
"${PYTHON:-python3}" -c "import pytest_timeout" 2> /dev/null && timeout_arg=(--timeout="${PER_TEST_S:-240}")
# -v: one line per test as it ends, so a run cut off by its time limit still names its failures.
timeout "${TEST_S:-420}" "${PYTHON:-python3}" -m pytest -v -n "${WORKERS:-16}" --dist loadfile \
  -p no:cacheprovider --durations=15 "${timeout_arg[@]}" "$@" > "$log" 2>&1
echo "pytest exit $?"
grep -E " (FAILED|ERROR) " "$log" | sed 's/^\[gw[0-9]*\] *\[ *[0-9]*%\] *//' | sort -u
tail -3 "$log"
cat "$HRGJAX_FAILURE_LOG" 2> /dev/null
