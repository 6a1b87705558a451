"""One evaluation of ``fit desired-speed`` under its default scenario, against the paper
experiment's (docs/fitting.md, "The default scenario"): interleaved, so the ratios hold under the
load of a shared machine.

    python benchmarks/fit_default_scenario.py [--rounds 3] [--seed 7]

The recording: 15 min of the paper's road and demand at the paper's estimates, instantaneous lane
changes (as ``sim run -c`` writes it). Each round times one evaluation (SUMO at the data start,
section crossings only, stratified desired speeds: what a restart's evaluation runs) under:

- ``paper``: ``fit.study.paper_scenario()``, what ``benchmarks/fit_paper_experiment.py`` fits with;
- ``recorded``: ``fit.recorded.recorded_scenario`` of the recording (the CLI's default now);
- ``runner``: ``Scenario()`` with the paper's speeds — an hour of demand, 3 s lane changes.

Prints the seconds per round and the median ratios to ``paper``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv: list[str]) -> dict:
    from aveas_format.fit import FitConfig
    from aveas_format.fit.optimize import metric_at
    from aveas_format.fit.recorded import recorded_scenario
    from aveas_format.fit.study import paper_scenario
    from aveas_format.sim import simulate
    from aveas_format.sim.runner import prepare_network
    from aveas_format.sim.scenario import Scenario

    rounds = int(argv[argv.index("--rounds") + 1]) if "--rounds" in argv else 3
    seed = int(argv[argv.index("--seed") + 1]) if "--seed" in argv else 7
    rec = simulate(paper_scenario().model_copy(update={"seed": seed}), recording=True).recording
    with tempfile.TemporaryDirectory() as tmp:  # as a user has it: written, opened
        import aveas_format

        rec = aveas_format.open(rec.write(Path(tmp) / "rec.aveas"))
        described = recorded_scenario([rec])
    paper = paper_scenario()
    runner = Scenario().with_desired_speeds({c.name: (c.speed_mean_kmh, c.speed_std_kmh)
                                             for c in paper.classes})
    scenarios = {"paper": paper, "recorded": described.scenario, "runner": runner}
    configs = {k: FitConfig(scenario=sc) for k, sc in scenarios.items()}
    networks = {k: prepare_network(sc.network) for k, sc in scenarios.items()}
    theta = np.array([131.05, 17.48, 89.22, 6.20])
    times: dict[str, list[float]] = {k: [] for k in scenarios}
    for _ in range(rounds):
        for k in scenarios:  # interleaved
            t0 = time.perf_counter()
            metric_at(theta, configs[k], networks[k])
            times[k].append(time.perf_counter() - t0)
    out = {"recorded_scenario": described.describe(), "rounds": rounds,
           "seconds": {k: [round(t, 2) for t in v] for k, v in times.items()},
           "ratio_to_paper": {k: round(float(np.median(np.array(v) / np.array(times["paper"]))), 2)
                              for k, v in times.items()}}
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main(sys.argv[1:])
