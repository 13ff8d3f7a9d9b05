"""Every benchmark in one run: one table, one JSON report (issue 17).

Runs each bench_*.py in a process of its own (as `python bench/bench_x.py` would), keeps what
it prints, collects the figures it records (common.record: value, same-run baseline, goal),
and writes bench/results/latest.json with the machine it ran on; then prints one table:
figure | value | baseline | goal | met. A bench that fails is a row saying so, and the run
exits non-zero at the end; a bench that cannot run here (no Chromium, say) says why.

    .venv/bin/python bench/report.py            # everything, under 10 minutes
    .venv/bin/python bench/report.py --quick    # the same code paths, shorter (CI)
    .venv/bin/python bench/report.py --markdown # latest.json's table, for docs/performance.md
    .venv/bin/python bench/report.py --plot     # docs/bench_load.png (in performance.md)
    .venv/bin/python bench/report.py --only bench_stop bench_state
    .venv/bin/python bench/report.py --soak     # with bench_soak's 10-minute run
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import REPORT_ENV

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "latest.json"

# name: (full run arguments, --quick arguments)
BENCHES = {
    "bench_rpc": ([], ["--quick"]),
    "bench_stop": ([], ["--quick"]),
    "bench_state": ([], ["--quick"]),
    "bench_motion_start": ([], ["--quick"]),
    "bench_lockstep": ([], ["--quick"]),
    "bench_cycle": (["--seconds", "8", "--lock-step-seconds", "8"],
                    ["--seconds", "3", "--lock-step-seconds", "3"]),
    "bench_collision": ([], ["--repeat", "2"]),
    "bench_planning": ([], ["--repeat", "2", "--sizes", "10", "100"]),
    "bench_jerk": ([], ["--quick"]),
    "bench_kinematics": ([], ["--poses", "200"]),
    "bench_crcl": ([], []),
    "bench_dashboard": (["8"], ["5"]),
    "bench_page": (["8"], ["3"]),
    "bench_events": ([], ["--quick"]),
    "bench_tracking": ([], ["--quick"]),
    "bench_security": ([], ["--quick"]),
    "bench_cell_loops": ([], ["--cycles", "500"]),
    "bench_soak": (["--seconds", "40"], ["--seconds", "20"]),
    "bench_faults": ([], ["--repeat", "2"]),
    "bench_bridges": ([], ["--quick"]),
}
# Every bench_*.py is in the report: one added without an entry fails the run at once.
_UNLISTED = sorted({p.stem for p in HERE.glob("bench_*.py")} - set(BENCHES))
PLOT = HERE.parent / "docs" / "bench_load.png"
TIMEOUT = 900   # s, one bench


def machine() -> dict:
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text()
                .splitlines() if line.startswith("model name")), platform.processor())
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, text=True,
                            capture_output=True).stdout.strip()
    return {"cpu": cpu, "cores": os.cpu_count(), "kernel": platform.release(),
            "python": platform.python_version(), "commit": commit,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "load_before": os.getloadavg()[0]}


def run(name: str, args: list[str]) -> dict:
    with tempfile.NamedTemporaryFile("r", suffix=".jsonl") as figures:
        env = {**os.environ, REPORT_ENV: figures.name}
        began = time.monotonic()
        try:
            done = subprocess.run([sys.executable, str(HERE / f"{name}.py"), *args], env=env,
                                  cwd=HERE.parent, text=True, capture_output=True,
                                  timeout=TIMEOUT)
            # The error's last lines (a gRPC status spans several), to say why it failed.
            error = "" if done.returncode == 0 else \
                f"exit code {done.returncode}: " + " | ".join(
                    line.strip() for line in done.stderr.strip().splitlines()[-8:])
            output = done.stdout
        except subprocess.TimeoutExpired as timeout:
            error, output = f"no result within {TIMEOUT} s", str(timeout.stdout or "")
        rows = [json.loads(line) for line in figures.read().splitlines() if line.strip()]
    return {"bench": name, "args": args, "seconds": round(time.monotonic() - began, 1),
            "error": error, "figures": rows,
            "output": "\n".join(line for line in output.splitlines()
                                if not line.startswith("argv[0]="))}


def met(row: dict) -> str:
    goal, value = row.get("goal"), row["value"]
    if goal is None or value is None or math.isnan(value):
        return ""
    return "yes" if (value >= goal if row["better"] == "higher" else value <= goal) else "no"


def number(x) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    return f"{x:,.0f}" if abs(x) >= 100 else f"{x:.3g}"


def table(report: dict, markdown: bool = False) -> str:
    head = ("figure", "value", "unit", "baseline", "goal", "met")
    lines = []
    for bench in report["benches"]:
        if bench["error"]:
            lines.append((f"{bench['bench']}: FAILED", bench["error"][:60], "", "", "", ""))
        for row in bench["figures"]:
            if row["figure"] == "skipped":
                lines.append((f"{bench['bench']}: skipped", row["baseline_name"], "", "", "", ""))
                continue
            base = number(row["baseline"])
            if base and row["baseline_name"]:
                base = f"{base} ({row['baseline_name']})"
            goal = row["goal"]
            goal_text = "" if goal is None else \
                f"{'>=' if row['better'] == 'higher' else '<='} {number(goal)}"
            lines.append((row["figure"], number(row["value"]), row["unit"], base, goal_text,
                          met(row)))
    if markdown:
        out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        out += ["| " + " | ".join(line) + " |" for line in lines]
        return "\n".join(out)
    widths = [max(len(str(c)) for c in column) for column in zip(head, *lines)]
    fmt = "  ".join(f"{{:{'<' if i in (0, 2, 3) else '>'}{w}}}" for i, w in enumerate(widths))
    return "\n".join([fmt.format(*head), "-" * (sum(widths) + 2 * len(widths))]
                     + [fmt.format(*line) for line in lines])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs (CI)")
    parser.add_argument("--markdown", action="store_true",
                        help="print the table of the last report as Markdown, run nothing")
    parser.add_argument("--plot", action="store_true",
                        help=f"plot the last report's figures that vary with load into "
                             f"{PLOT.relative_to(HERE.parent)}, run nothing")
    parser.add_argument("--only", nargs="+", choices=sorted(BENCHES), help="these benches only")
    parser.add_argument("--soak", action="store_true", help="bench_soak for 10 minutes")
    args = parser.parse_args()
    if _UNLISTED:
        sys.exit(f"bench/report.py: add {', '.join(_UNLISTED)} to BENCHES")
    if args.plot:
        from plot import plot_report   # matplotlib: only here
        plot_report(json.loads(RESULTS.read_text()), PLOT)
        print(f"wrote {PLOT.relative_to(HERE.parent)}")
        return
    if args.markdown:
        report = json.loads(RESULTS.read_text())
        print(f"Measured {report['machine']['date']} on {report['machine']['cpu']} "
              f"({report['machine']['cores']} cores, load {report['machine']['load_before']:.1f}"
              f", commit {report['machine']['commit']}{', quick' if report['quick'] else ''}):\n")
        print(table(report, markdown=True))
        return
    report = {"machine": machine(), "quick": args.quick, "benches": []}
    for name in args.only or BENCHES:
        full, quick = BENCHES[name]
        print(f"== {name}", flush=True)
        result = run(name, ["--soak"] if args.soak and name == "bench_soak"
                     else quick if args.quick else full)
        print(result["output"] + (f"\n{name} FAILED: {result['error']}" if result["error"]
                                  else ""), flush=True)
        report["benches"].append(result)
    report["machine"]["load_after"] = os.getloadavg()[0]
    # A partial run does not stand for the latest report.
    out = RESULTS.with_name("only.json") if args.only else RESULTS
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(report, indent=1, allow_nan=True))
    print(f"\n{table(report)}\n\nreport: {out.relative_to(HERE.parent)}")
    if any(bench["error"] for bench in report["benches"]):
        sys.exit(1)


if __name__ == "__main__":
    main()
