#!/bin/sh
# one scenario at a time: shipped vs the guard-hold fix on the scenarios the escape turn and the backfire rule were made for
export PYTHONPATH=../../.. OMP_NUM_THREADS=1
for spec in "3 hard_101" "3 hard_195" "5 hard_012" "13 hard_064" "13 hard_023" "15 hard_094"; do
  set -- $spec
  for fix in none guardhold; do
    if [ $fix = none ]; then a=""; else a="--fix $fix"; fi
    echo "seed $1 $2 $fix $(nice -n 19 ../../../.venv/bin/python trace.py $1 $2 run_s$1_$2_$fix.json $a 2>&1 | tail -1)"
  done
done
