"""Mean ± standard error over training seeds of the closed-loop evaluations in a folder (Markdown table)."""

import json
import statistics
import sys
from collections import defaultdict
from pathlib import Path

groups = defaultdict(list)
for path in sorted(Path(sys.argv[1]).glob("*.json")):
    r = json.loads(path.read_text())
    execution = path.stem.rsplit("-", 1)[1]
    groups[(r["method"], "Multi2D" if r["multi_task"] else "single-task", execution)].append(r)


def mean_se(values):
    se = statistics.stdev(values) / len(values) ** 0.5 if len(values) > 1 else float("nan")
    return f"{statistics.mean(values):.1f} ± {se:.1f}"


print("| method | tasks | execution | seeds | score (minari) | score (d4rl) | success | calls/episode "
      "| decision ms p50 / p95 (batch 1) | floor: line (minari) |")
print("|---|---|---|---|---|---|---|---|---|---|")
for (method, tasks, execution), rs in sorted(groups.items()):
    calls = statistics.mean(r.get("calls_per_episode", r["nfe"]) for r in rs)
    latency = [r["decision_ms_batch1"] for r in rs if r.get("decision_ms_batch1")]
    minari, d4rl = ([r["score"][c]["mean"] for r in rs] for c in ("minari", "d4rl"))
    print(f"| {method} | {tasks} | {execution} | {len(rs)} | {mean_se(minari)} | {mean_se(d4rl)} | "
          f"{statistics.mean(r['success_rate']['mean'] for r in rs):.2f} | {calls:.0f} | "
          + (f"{statistics.mean(x['p50'] for x in latency):.1f} / {statistics.mean(x['p95'] for x in latency):.1f}"
             if latency else "-")
          + f" | {mean_se([r['floor_line']['score']['minari']['mean'] for r in rs])} |")
