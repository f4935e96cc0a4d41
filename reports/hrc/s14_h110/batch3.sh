#!/bin/sh
# more development scenarios with the per-body-part sweep rule (and shipped where no committed baseline exists)
export PYTHONPATH=../../.. OMP_NUM_THREADS=1
for spec in "13 hard_094 sphere" "3 hard_075 sphere" "1 hard_038 sphere" "1 hard_084 sphere" "3 hard_109 none" "3 hard_109 sphere" "11 hard_106 none" "11 hard_106 sphere"; do
  set -- $spec
  if [ $3 = none ]; then a=""; else a="--fix $3"; fi
  echo "seed $1 $2 $3 $(nice -n 19 ../../../.venv/bin/python trace.py $1 $2 run_s$1_$2_$3.json $a 2>&1 | tail -1)"
done
