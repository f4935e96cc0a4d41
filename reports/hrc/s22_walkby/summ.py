import json, sys
for p in sys.argv[1:]:
    d = json.load(open(p))
    print(p.split('/')[-1], 'coll', d['collisions'], d.get('collided'), 'min', d['min_separation_m'], 'share', d['productive_time_share'],
          'walkby/h', d['false_stops_per_worker_hour'], d['walkby_stops'], d['walkby_stops_by_reason'], 'halts', d['halts'], 'notrun', d['not_run'])
