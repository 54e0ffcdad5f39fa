"""OGBench manipulation's speed against what it cannot do without, each side timed in one process (alternated rounds,
after an untimed short run of each), written with the code version and the machine's load to a JSON file:

- ``generation``: the data recipe against its environment and plan oracles stepping alone;
- ``evaluation``: the protocol with a policy (GCBC's network at OGBench's size, untrained: its cost, not its score)
  against the protocol's environments stepped alone (a zero action) plus the policy's calls as timed inside it.

``python scripts/manip-speed.py generation|evaluation OUT.json [NAME ...]``. One process on one core; other jobs on
the machine slow both sides alike.
"""

import json
import os
import platform
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

from bridgeplan.device import configure_threads  # noqa: E402
from bridgeplan.envs.ogbench_manipulation.generate import measure_overhead  # noqa: E402
from bridgeplan.envs.ogbench_manipulation.protocol import measure_evaluation  # noqa: E402
from bridgeplan.files import atomic_write_text, code_version  # noqa: E402

what, out, names = sys.argv[1], sys.argv[2], sys.argv[3:] or ["cube-single-play-v0"]
configure_threads(1)
if what == "generation":
    rows = [measure_overhead(n, episodes=2, episode_steps=1001, rounds=3) for n in names]
    ratio = "recipe_over_stepping"
elif what == "evaluation":
    rows = [measure_evaluation(n, episodes_per_task=4, rounds=2) for n in names]
    ratio = "evaluation_over_parts"
else:
    sys.exit(f"error: generation or evaluation, got {what!r}")
atomic_write_text(Path(out), json.dumps(
    {"code_version": code_version(), "machine": platform.machine(), "cpus": os.cpu_count(),
     "load_average_1min": os.getloadavg()[0], "rows": rows}, indent=2) + "\n")
for r in rows:
    print(f"{r['dataset']}: {ratio} {r[ratio]:.2f}")
