#!/bin/bash
# interleaved prof_cycle runs: base18 and perfB, tag $1, rounds $2
TAG=$1; N=${2:-3}
for r in $(seq $N); do
  for t in base18 perfB; do
    echo "== $t $TAG round $r start $(date -u +%H:%M:%S) load $(cut -d' ' -f1 /proc/loadavg)"
    (cd $( [ $t = base18 ] && echo /work/wt/base18 || echo $SNAP ) && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. /work/main/.venv/bin/python /work/wt/perfB/reports/bench/s15_perf/prof_cycle.py --seconds 60 --out /tmp/perfB/$TAG-$t-$r.json | head -16)
  done
done
echo DONE
