"""Classify every halt (NORMAL -> not NORMAL) of a traced scenario by what caused it."""
import json, sys
for n in sys.argv[1:]:
    d = json.load(open(n))
    fr = d['frames']; steps = {round(s['t'], 2): s for s in d['steps']}
    prev = 'NORMAL'
    for i, f in enumerate(fr):
        if f['state'] != 'NORMAL' and prev == 'NORMAL' and f['t'] > -0.4:
            w = str(f['worker']) if f['worker'] is not None else None
            p = f['people']
            st = steps.get(round(f['t'], 2)) or min(d['steps'], key=lambda s: abs(s['t'] - f['t']))
            true = {k: v['true_sep_caps_m'] for k, v in st['per'].items()}
            src = []
            for k, v in p.items():
                if 'lifted_sep_m' in v: src.append(f"{k}:lifted{v['lifted_sep_m']}")
                if 'lost_age_s' in v: src.append(f"{k}:lost{v['lost_age_s']}")
                if 'ray_bound_m' in v: src.append(f"{k}:ray{v['ray_bound_m']}@{v['ray_age_s']}")
            print(n.split('/')[-1][:-5], f['t'], f['state'], f['reason'][:40], 'd', f['d'], 'coming', f['coming'],
                  'lost', f['lost_stop'], 'unl', f['unlifted_stop'], src, 'true', true)
        prev = f['state']
