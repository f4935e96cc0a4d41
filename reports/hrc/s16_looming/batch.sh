#!/bin/sh
# loomtrace.py over SEED:NAME arguments, one at a time, niced; one summary line per scenario into runs.txt
cd "$(dirname "$0")/../../.." || exit 1
for sn in "$@"; do
  s=${sn%%:*}; n=${sn#*:}
  OMP_NUM_THREADS=1 PYTHONPATH=. nice -n 10 /work/main/.venv/bin/python reports/hrc/s16_looming/loomtrace.py "$s" "$n" \
    "reports/hrc/s16_looming/out/${s}_${n}.json" | sed "s/^/$s /" >> reports/hrc/s16_looming/runs.txt
done
