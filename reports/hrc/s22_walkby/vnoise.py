"""Tracker velocity error in the hard world: LS over 0.5 s of lifted heads (the runtime's fit, resets on gaps)
against the truth's head velocity; per frame, the approach (toward the effector) error."""
import json, sys
import numpy as np
def fit(ts, xs):
    ts = np.array(ts); xs = np.array(xs); tc = ts - ts.mean()
    return tc @ (xs - xs.mean(0)) / (tc @ tc)
errs = {0.5: [], 1.0: []}; spans = []
for n in sys.argv[1:]:
    d = json.load(open(n)); fr = d['frames']; steps = d['steps']
    st_t = np.array([s['t'] for s in steps])
    for i, f in enumerate(fr):
        for w, p in f['people'].items():
            if 'lifted_head' not in p: continue
            t = f['t']
            for win in errs:
                hist = []
                for g in reversed(fr[max(0, i - 60):i + 1]):
                    if g['t'] < t - win: break
                    if w in g['people'] and 'lifted_head' in g['people'][w]: hist.append((g['t'], g['people'][w]['lifted_head']))
                if len(hist) < 3 or hist[0][0] - hist[-1][0] < 0.3: continue
                v = fit([h[0] for h in hist], [h[1] for h in hist]); v[1] = 0
                k = int(np.argmin(abs(st_t - t))); ee = np.array(steps[k]['ee'])
                if w not in steps[k]['per']: continue
                th = [(steps[j]['t'], steps[j]['per'][w]['head']) for j in range(max(0, k - 25), k + 1) if w in steps[j]['per']]
                if len(th) < 10: continue
                vt = fit([h[0] for h in th], [h[1] for h in th]); vt[1] = 0
                tp = np.array(th[-1][1]); tow = ee - tp; tow[1] = 0; tow /= np.linalg.norm(tow)
                errs[win].append((float(v @ tow), float(vt @ tow)))
for win, e in errs.items():
    e = np.array(e); err = e[:, 0] - e[:, 1]
    still = np.abs(e[:, 1]) < 0.2
    print(f"window {win}s: n {len(e)}  approach error sd {err.std():.2f}  p95 |err| {np.percentile(abs(err), 95):.2f}  p99 {np.percentile(abs(err),99):.2f}"
          f"  | true |appr|<0.2 (n {still.sum()}): est > 0.3 share {np.mean(e[still,0] > 0.3):.3f}, > 0.6 {np.mean(e[still,0] > 0.6):.3f}, > 0.8 {np.mean(e[still,0] > 0.8):.3f}")
