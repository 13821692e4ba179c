"""Render the README's benchmark table from benchmarks/results/*.json (numbers are never typed in).

    python -m benchmarks.table            # print the table
    python -m benchmarks.table --write    # replace the block between the markers in README.md
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
BEGIN, END = "<!-- bench-table:begin -->", "<!-- bench-table:end -->"
TIERS = [("cpu", ["cpu"]), ("h100", ["h100-warp", "h100-warp-tight", "h100-e2e", "h100-jax"]), ("h200", ["h200"]), ("h200-x2", ["h200-x2"])]


def _rows(files: list[str]):
    for f in files:
        p = RESULTS / f"{f}.json"
        if p.exists():
            r = json.loads(p.read_text())
            for name, b in r["backends"].items():
                for row in b.get("rows", []):
                    yield r, name, b, row


def render() -> str:
    lines = ["| tier | device | backend | batch | steps/s | 4096 seeds x 160 steps at this rate (s) | compile (s) | status |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for tier, files in TIERS:
        rows = list(_rows(files))
        if not rows:
            lines.append(f"| {tier} | - | - | - | - | - | - | pending |")
            continue
        for r, name, b, row in rows:
            if "steps_per_second" not in row:
                lines.append(f"| {tier} | {r['device']} | {name} | {row['batch']:,} | failed: {row['error'][:60]} | - | - | measured |")
                continue
            sweep = 4096 * r["total_steps"] / row["steps_per_second"]
            lines.append(f"| {tier} | {r['device']} | {name} ({b['device']}) | {row['batch']:,} | "
                         f"{row['steps_per_second']:,.0f} | {sweep:.2f} | {row['compile_seconds']:.1f} | measured {r['date']} |")
    e2e = [json.loads((RESULTS / f"{f}.json").read_text()).get("end_to_end") for _, fs in TIERS for f in fs
           if (RESULTS / f"{f}.json").exists()]
    for tier_files, e in zip([f for _, fs in TIERS for f in fs if (RESULTS / f"{f}.json").exists()], e2e):
        if e:
            lines.append("")
            lines.append(f"End to end ({tier_files}): {e['n_seeds']:,} seeds on {e['backend']} (start poses, compile, "
                         f"rollout, per_seed.parquet written) in {e['wall_seconds']:.1f} s.")
    return "\n".join(lines)


def main(argv=None) -> int:
    table = render()
    if "--write" in (argv or sys.argv[1:]):
        readme = ROOT / "README.md"
        text = readme.read_text()
        a, b = text.index(BEGIN) + len(BEGIN), text.index(END)
        readme.write_text(text[:a] + "\n" + table + "\n" + text[b:])
    else:
        print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
