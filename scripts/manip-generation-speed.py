"""Measure OGBench manipulation's data recipe against its environment and oracles stepping alone, in one process, and
write the figures (with the code version and the machine) to a JSON file: ``python scripts/manip-generation-speed.py
OUT.json [NAME ...]``. One torch-free process on one core; other jobs on the machine slow both sides alike."""

import json
import os
import platform
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

from bridgeplan.envs.ogbench_manipulation.generate import measure_overhead  # noqa: E402
from bridgeplan.files import atomic_write_text, code_version  # noqa: E402

out, names = sys.argv[1], sys.argv[2:] or ["cube-single-play-v0"]
rows = [measure_overhead(n, episodes=2, episode_steps=1001, rounds=3) for n in names]
atomic_write_text(__import__("pathlib").Path(out), json.dumps(
    {"code_version": code_version(), "machine": platform.machine(), "cpus": os.cpu_count(),
     "load_average_1min": os.getloadavg()[0], "rows": rows}, indent=2) + "\n")
for r in rows:
    print(f"{r['dataset']}: recipe {r['recipe_steps_per_s']:.0f} steps/s, stepping alone "
          f"{r['stepping_alone_steps_per_s']:.0f} steps/s, ratio {r['recipe_over_stepping']:.2f}")
