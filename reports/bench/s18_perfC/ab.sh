#!/bin/bash
# interleaved A/B of prof_cycle: base (4e7d563, /work/wt/base18) vs MINE (a git archive of this branch, default /tmp/perfC/snap); $1 = tag, $2 = rounds; ORDER="mine base" runs this tree first in each round
tag=$1; rounds=${2:-3}
for i in $(seq 1 $rounds); do
  for side in ${ORDER:-base mine}; do
    if [ $side = base ]; then dir=/work/wt/base18; else dir=${MINE:-/tmp/perfC/snap}; fi
    cd $dir && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. /work/main/.venv/bin/python /work/wt/perfC/reports/bench/s15_perf/prof_cycle.py --seconds 60 --out /tmp/perfC/ab_${tag}_${side}_$i.json > /tmp/perfC/ab_${tag}_${side}_$i.log 2>&1
    echo "$(date -u +%H:%M:%S) $side $i done: $(head -1 /tmp/perfC/ab_${tag}_${side}_$i.log | cut -c1-120)"
  done
done
