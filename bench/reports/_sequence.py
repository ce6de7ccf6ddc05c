"""A sequence's report (``OUT/report.md`` of ``bench sequence``): every entry's status with a
link to its report, from the rows :mod:`bench.sequence` reads from the entries' run
directories (moved here from bench/sequence.py: the report package makes the words)."""

from __future__ import annotations

from pathlib import Path


def sequence_md(out: Path, name: str, rows: list[dict], not_started: str) -> str:
    """The sequence report's markdown: how many entries completed, and a row per entry (its
    steps unless its status is ``not_started``)."""
    done = sum(r["status"] == "completed" for r in rows)
    lines = [f"# Sequence: {name}", "",
             f"{done} of {len(rows)} entries completed"
             + ("." if done == len(rows) else f"; `bench resume {out}` goes on at the first that did not."), "",
             "| # | entry | plan | rig | labels | status | steps | report |", "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows, 1):
        labels = ", ".join(f"{k}={v}" for k, v in r["labels"].items())
        link = f"[report]({r['report']})" if r["report"] else ""
        steps = f"{r['steps_done']}/{r['steps_total']}" if r["status"] != not_started else ""
        lines.append(f"| {i} | {r['name']} | {r['plan_file']} | {r['rig_file']} | {labels} | {r['status']} | {steps} "
                     f"| {link} |")
    return "\n".join(lines) + "\n"
