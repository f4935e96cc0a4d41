"""At each 'coming' halt: the tracker's approach speed (LS fit over 0.5 s of lifted heads) vs the truth's."""
import json, sys
import numpy as np
def fit(ts, xs):
    ts = np.array(ts); xs = np.array(xs); tc = ts - ts.mean()
    return tc @ (xs - xs.mean(0)) / (tc @ tc)
for n in sys.argv[1:]:
    d = json.load(open(n)); fr = d['frames']; steps = d['steps']
    prev = 'NORMAL'
    for f in fr:
        if f['state'] == 'LEVEL2' and prev == 'NORMAL' and f['coming']:
            w = str(f['worker']); t = f['t']
            hist = [(g['t'], g['people'][w]['lifted_head']) for g in fr if t - 0.5 <= g['t'] <= t and w in g['people'] and 'lifted_head' in g['people'][w]]
            ee = np.array(min(steps, key=lambda s: abs(s['t'] - t))['ee'])
            v = fit([h[0] for h in hist], [h[1] for h in hist]); v[1] = 0
            pos = np.array(hist[-1][1])
            tow = (ee - pos); tow[1] = 0; tow /= np.linalg.norm(tow)
            th = [(s['t'], s['per'][w]['head']) for s in steps if t - 0.5 <= s['t'] <= t and w in s['per']]
            vt = fit([h[0] for h in th], [h[1] for h in th]); vt[1] = 0
            tp = np.array(th[-1][1]); tt = ee - tp; tt[1] = 0; tt /= np.linalg.norm(tt)
            print(n.split('/')[-1][:-5], t, 'n', len(hist), 'est approach %.2f speed %.2f' % (v @ tow, np.linalg.norm(v)),
                  '| true approach %.2f speed %.2f' % (vt @ tt, np.linalg.norm(vt)), 'd', f['d'])
        prev = f['state']
