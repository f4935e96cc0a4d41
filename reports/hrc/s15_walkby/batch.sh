#!/bin/sh
# usage: batch.sh FIX OUTLIST seed:name ...   (FIX "" = shipped; OUTLIST relative to the worktree root, one line per
# scenario appended; traces to out/, not committed); one scenario at a time
cd "$(dirname "$0")/../../.." || exit 1
fix=$1; out=$2; shift 2
for sn in $*; do
  seed=${sn%%:*}; name=${sn#*:}
  tag=${fix:-shipped}
  OMP_NUM_THREADS=1 nice -n 10 /work/main/.venv/bin/python reports/hrc/s15_walkby/wtrace.py "$seed" "$name" \
    "reports/hrc/s15_walkby/out/${seed}_${name}_${tag}.json" ${fix:+--fix "$fix"} 2>&1 | tail -1 | sed "s/^/$tag seed=$seed /" >> "$out"
done
