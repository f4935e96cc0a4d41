#!/bin/sh
# the per-body-part sweep rule (fix_sphere.py), one scenario at a time
export PYTHONPATH=../../.. OMP_NUM_THREADS=1
for spec in "15 hard_110" "3 hard_195" "3 hard_101" "5 hard_012" "13 hard_064" "13 hard_023" "15 hard_094" "15 hard_006"; do
  set -- $spec
  echo "seed $1 $2 sphere $(nice -n 19 ../../../.venv/bin/python trace.py $1 $2 run_s$1_$2_sphere.json --fix sphere 2>&1 | tail -1)"
done
