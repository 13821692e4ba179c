"""Render the docs' benchmark table (docs/benchmarks.md) from benchmarks/results/*.json (numbers are never typed in).

    python -m benchmarks.table            # print the table
    python -m benchmarks.table --write    # replace the block between the markers in docs/benchmarks.md
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PAGE = ROOT / "docs" / "benchmarks.md"  # the page whose table this is
BEGIN, END = "<!-- bench-table:begin -->", "<!-- bench-table:end -->"
# Each tier's current results; superseded runs live in results/history/ and docs/notebook.md.
TIERS = [("cpu", ["cpu"]), ("h100", ["h100", "h100-jax", "h100-task"]), ("h200", ["h200"]), ("h200-x2", ["h200-x2"])]


def _load(name: str) -> dict | None:
    p = RESULTS / f"{name}.json"
    return json.loads(p.read_text()) if p.exists() else None


def _best(b: dict) -> dict | None:
    rows = [r for r in b.get("rows", []) if "steps_per_second" in r]
    return max(rows, key=lambda r: r["steps_per_second"]) if rows else None


def render() -> str:
    lines = ["| tier | device | backend | batch | steps/s | 4096 seeds x 160 steps at this rate (s) | first call (s) | status |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    notes = []
    for tier, files in TIERS:
        results = [(f, r) for f in files if (r := _load(f))]
        if not results:
            lines.append(f"| {tier} | - | - | - | - | - | - | pending |")
            continue
        for f, r in results:
            for name, b in r["backends"].items():
                for row in b.get("rows", []):
                    if "steps_per_second" not in row:
                        lines.append(f"| {tier} | {r['device']} | {name} | {row['batch']:,} | failed: {row['error'][:60]} "
                                     f"| - | - | measured {r['date']} |")
                        continue
                    sweep = 4096 * r["total_steps"] / row["steps_per_second"]
                    lines.append(f"| {tier} | {r['device']} | {name} ({b['device']}) | {row['batch']:,} | "
                                 f"{row['steps_per_second']:,.0f} | {sweep:.2f} | {row['first_call_seconds']:.1f} | "
                                 f"measured {r['date']} |")
            cpu = _best(r["backends"].get("cpu", {}))
            for name, b in r["backends"].items():
                best = _best(b)
                if name != "cpu" and best and cpu:
                    notes.append(f"{tier} ({f}.json): {name} peaks at {best['steps_per_second'] / 1e6:.3g} M steps/s "
                                 f"(batch {best['batch']:,}), {best['steps_per_second'] / cpu['steps_per_second']:.3g}x "
                                 f"the same run's all-core CPU rollout ({cpu['steps_per_second'] / 1e6:.3g} M, "
                                 f"{r['backends']['cpu'].get('threads', '?')} threads).")
                if "rate_over_open_loop" in b:
                    ratio = ", ".join(f"{int(k):,}: {v:.2f}" for k, v in b["rate_over_open_loop"].items())
                    notes.append(f"{tier} ({f}.json): {name} ({b.get('scenario', 'closed loop')}) runs at this fraction "
                                 f"of the same run's open-loop rate, per batch: {ratio}.")
                if "scaling_efficiency" in b:
                    eff = ", ".join(f"{int(k):,}: {v:.2f}" for k, v in b["scaling_efficiency"].items())
                    notes.append(f"{tier}: {name} scaling efficiency (K-device rate / K x one-device rate, same batch): {eff}.")
            e = r.get("end_to_end")
            if e and f == files[0]:
                on = f" ({e['device']})" if "device" in e else ""
                notes.append(f"{tier}: end to end, {e['n_seeds']:,} seeds on {e['backend']}{on} (start poses, compile, "
                             f"rollout, per_seed.parquet written) in {e['wall_seconds']:.1f} s.")
    return "\n".join(lines + [""] + [f"- {n}" for n in notes])


def main(argv=None) -> int:
    table = render()
    if "--write" in (argv or sys.argv[1:]):
        text = PAGE.read_text()
        a, b = text.index(BEGIN) + len(BEGIN), text.index(END)
        PAGE.write_text(text[:a] + "\n\n" + table + "\n" + text[b:])  # a blank line: the comment is its own block
    else:
        print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
