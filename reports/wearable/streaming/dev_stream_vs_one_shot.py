"""Development drives (drive-eval seeds 1 and 5): streaming steps vs the one-shot model on prefixes (session 9's
path), same int8 precision, same policy: event scores of each and how many decisions change."""
import json, sys, time
from edge_runtime import config
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa
from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.command import replay
from firmware_sim.scenarios.drive_eval import ModeScore, held_out_drives
cfg = config.load(None)
eng = {"stream": Engine.from_manifest(ASSETS_DIR, "int8"), "one_shot": Engine.from_manifest(ASSETS_DIR, "int8", stream=False)}
assert eng["stream"].streaming and not eng["one_shot"].streaming
out = {}
for seed in (int(s) for s in sys.argv[1].split(",")):
    drives = list(held_out_drives(10.0, seed, 0.3, 30.0))
    res = {}
    for mode in ("full_window", "early"):
        mcfg = config.override(cfg, "alerts", decision=mode)
        scores = {k: ModeScore(detector=cfg.detector, attribution="trigger") for k in eng}
        n = changed = changed_alert = 0
        examples = []
        for d in drives:
            dec = {}
            for k, e in eng.items():
                lst = []
                replay(mcfg, e, d.acc_mps2, outputs=[lambda x, o=lst: o.append(x.to_json())])
                scores[k].add(d, lst)
                dec[k] = [(x["t_trigger_s"], x["steps"], x["status"], x["label"], x["alerted"], x["t_alert_s"]) for x in lst]
            a, b = set(dec["stream"]), set(dec["one_shot"])
            n += len(dec["one_shot"])
            diff = b - a
            changed += len(diff)
            changed_alert += len([x for x in diff if x[4]]) + len([x for x in a - b if x[4]])
            examples += sorted(diff)[:2]
        res[mode] = {"decisions_one_shot": n, "decisions_stream": None, "one_shot_decisions_not_made_by_stream": changed,
                     "alerting_decisions_differing": changed_alert,
                     "scores": {k: {f: v for f, v in s.as_dict().items() if f in ("event_recall", "first_alert_class_accuracy", "onset_to_first_alert_s", "false_alerts_per_hour", "distractions", "alerted")} for k, s in scores.items()},
                     "examples": examples[:6]}
        print(seed, mode, json.dumps(res[mode])[:1500], flush=True)
    out[seed] = res
json.dump(out, open(sys.argv[2], "w"), indent=1)
