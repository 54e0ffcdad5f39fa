"""The replanning expert on the evaluation episodes themselves: its normalized score (both conventions) on the
200 single-task and the 200 Multi2D episodes of task seeds 0, 1, 2 of each maze. Normalized scores divide by the
expert's return on single-task episodes (the shipped reference), so on Multi2D's random goals, often near the
start, a planner may pass 100; this says where the expert itself stands there.

Usage: python docs/results/expert_on_tasks.py OUT.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bridgeplan.files import code_version
from bridgeplan.maze.expert import WaypointExpert
from bridgeplan.maze.layouts import get_maze
from bridgeplan.maze.reference import normalized_score
from bridgeplan.maze.rollout import rollout
from bridgeplan.maze.tasks import sample_tasks

EPISODES, SEEDS = 200, (0, 1, 2)


def main(out: str) -> int:
    rows = []
    for name in ("umaze", "medium", "large"):
        maze = get_maze(name)
        for multi in (False, True):
            for seed in SEEDS:
                starts, goals = sample_tasks(maze, EPISODES, seed, multi_task=multi)
                expert = WaypointExpert(maze)
                expert.plan(starts, goals)
                result = rollout(maze, lambda t, obs: expert(obs), starts, goals)
                score = {c: normalized_score(name, result.returns, c)[0] for c in ("minari", "d4rl")}
                rows.append({"maze": name, "multi_task": multi, "seed": seed, "score_minari": score["minari"],
                             "score_d4rl": score["d4rl"], "success": float(result.success.mean())})
                print(rows[-1])
    Path(out).write_text(json.dumps({"code_version": code_version(), "episodes": EPISODES, "rows": rows},
                                    indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
