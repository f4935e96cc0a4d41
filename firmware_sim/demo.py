"""``python -m firmware_sim.demo``: the product on simulated devices (see firmware_sim/scenarios/demo.py)."""
from firmware_sim.scenarios.demo import main

if __name__ == "__main__":
    raise SystemExit(main())
