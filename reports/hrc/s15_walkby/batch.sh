#!/bin/sh
# usage: batch.sh FIX OUTLIST seed:name ...   (FIX "" = shipped; OUTLIST relative to the worktree root, one line per
# scenario appended; traces to out/, not committed); one scenario at a time. TRACE (default wtrace.py), FLAG (its
# candidate option, default --fix) and OUTDIR (default reports/hrc/s15_walkby/out) choose another tracer
# (s16_walkby2/jtrace.py with FLAG=--cand)
cd "$(dirname "$0")/../../.." || exit 1
trace=${TRACE:-reports/hrc/s15_walkby/wtrace.py}; flag=${FLAG:---fix}; outdir=${OUTDIR:-reports/hrc/s15_walkby/out}
mkdir -p "$outdir"
fix=$1; out=$2; shift 2
for sn in $*; do
  seed=${sn%%:*}; name=${sn#*:}
  tag=${fix:-shipped}
  OMP_NUM_THREADS=1 nice -n 10 /work/main/.venv/bin/python "$trace" "$seed" "$name" \
    "$outdir/${seed}_${name}_${tag}.json" ${fix:+$flag "$fix"} 2>&1 | tail -1 | sed "s/^/$tag seed=$seed /" >> "$out"
done
