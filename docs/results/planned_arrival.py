"""When do plans reach the goal? For each run given, the first planned state within 0.45 of the goal
(``replan.arrival_index``) of its open-loop plans on the 200 single-task episodes of its training seed's task
seed, at NFE 2, from the final snapshot; writes one JSON (median, mean, share arriving before the plan's last
state) and prints it.

Usage: python docs/results/planned_arrival.py OUT.json RUN [RUN ...]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import torch

from bridgeplan.files import code_version
from bridgeplan.maze.layouts import get_maze
from bridgeplan.maze.tasks import sample_tasks
from bridgeplan.replan import arrival_index
from bridgeplan.runs import load_planner


def main(out: str, runs: list[str]) -> int:
    torch.set_num_threads(1)
    rows = []
    for run in runs:
        planner, info = load_planner(Path(run), device="cpu")
        seed = info.config.seed
        starts, goals = sample_tasks(get_maze(info.config.maze), 200, seed)
        states = np.concatenate([starts, np.zeros_like(starts)], axis=1)
        plan = planner.plan(states, goals, nfe=2, generator=torch.Generator().manual_seed(seed))
        arrival = arrival_index(plan.states, goals)
        last = plan.states.shape[1] - 1
        rows.append({"run": info.name, "step": info.step, "plan_steps": last + 1,
                     "arrival_median": float(np.median(arrival)), "arrival_mean": float(arrival.mean()),
                     "share_before_last": float((arrival < last).mean())})
    Path(out).write_text(json.dumps({"code_version": code_version(), "episodes": 200, "nfe": 2, "runs": rows},
                                    indent=2) + "\n")
    print(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2:]))
