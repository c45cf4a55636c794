"""Prints the markdown tables of docs/RESULTS.md from the summaries under a results directory
(written by scripts/results.sh)."""
import json
import sys
from pathlib import Path

out = Path(sys.argv[1])


def summary(name):
    return json.loads((out / name / "summary.json").read_text())


def first_last(name, agent=1):
    """UAV1's smoothed curve: its first full window, at 10% of the run, and its end."""
    window = summary(name)["smoothing_window"]
    rows = [line.split(",") for line in (out / name / "curve.csv").read_text().splitlines()[1:]]
    values = [float(r[3]) for r in rows if r[1] == str(agent)]
    return values[min(window, len(values)) - 1], values[len(values) // 10], values[-1]


def fmt(x):
    return "-" if x is None else f"{x:.2f}"


print("| run | UAV1 curve: first window / at 10% / end | UAV1 final mean (last 1000) | UAV1 greedy | greedy truncated | UAV1 optimum alone / knowing target |")
print("|---|---|---|---|---|---|")
for name in ["fig10/s1", "fig11/s2-none", "fig11/s3-flags", "s3-none", "s3-flags", "s3-compact", "n8-none", "n8-flags", "n8-compact"]:
    s = summary(name)
    a, b, c = first_last(name)
    print(f"| `{name}` | {a:.1f} / {b:.1f} / {c:.1f} | {fmt(s['final_mean_episode_length'])} | {fmt(s['greedy_episode_length'][0])} "
          f"| {s['greedy_truncated'][0]} of {s['greedy_episodes'][0]} | {fmt(s['optimum_memoryless'][0])} / {fmt(s['optimum_known_target'][0])} |")

print()
print("| run | UAVs | wall s | rounds/s | env-steps/s | mean final length (all UAVs) | mean greedy (all UAVs) | peak RSS KiB: supervisor / world / largest agent |")
print("|---|---|---|---|---|---|---|---|")
for name in ["scale-1", "scale-2", "scale-4", "scale-8", "scale-16", "scale-32", "n8-20000", "n32-5000"]:
    s = summary(name)
    finals = [x for x in s["final_mean_episode_length_per_agent"] if x is not None]
    greedy = [x for x in s["greedy_episode_length"] if x is not None]
    rss = {p["process"]: p["kib"] for p in s["peak_rss_kib"]}
    agents = max((v for k, v in rss.items() if k.startswith("UAV")), default=0)
    print(f"| `{name}` ({s['scenario']}, {s['comm']}) | {s['uavs']} | {s['wall_seconds']:.1f} | {s['rounds_per_second']:.0f} "
          f"| {s['env_steps_per_second']:.0f} | {sum(finals) / len(finals):.2f} | {sum(greedy) / max(len(greedy), 1):.2f} "
          f"| {rss.get('supervisor', 0)} / {rss.get('world', 0)} / {agents} |")
