#!/bin/bash
# Sequential runs (one heavy job at a time): record_states.py over hrc hard:60, for each
# "seed protection tag [extra hrc args...]" line on stdin. Logs the UTC start and end of each.
D=reports/hrc/s17_prodshare
while read -r seed prot tag extra; do
  [ -z "$seed" ] && continue
  echo "$(date -u +%FT%TZ) start seed $seed $prot $tag $extra"
  OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. /work/main/.venv/bin/python $D/record_states.py \
    $D/seg_${tag}_seed${seed}_${prot}.json.gz -- --scenario hard:60 --seed "$seed" --link can --max-speed 2.0 \
    --perception lifter --protection "$prot" --json $D/hard60_${tag}_seed${seed}_${prot}.json --jobs 1 --quiet $extra \
    2>&1 | tail -2
  echo "$(date -u +%FT%TZ) end seed $seed $prot $tag"
done
