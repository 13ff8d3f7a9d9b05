"""The report's figures that vary with load, one PNG for docs/performance.md (report.py --plot).

Four panels from bench/results/latest.json, each beside its same-run baseline: unary call
latency against the number of concurrent clients (bench_rpc), event latency against the
number of subscribers (bench_state), stop latency with the server idle and busy (bench_stop),
and resident memory through the soak (bench_soak).
"""
from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")   # files only: no display on a build machine
import matplotlib.pyplot as plt  # noqa: E402

RPCS = ("GetRobotPosition", "GetDeviceState", "SetSpeed")


def _figures(report: dict) -> dict[str, dict]:
    return {row["figure"]: row for bench in report["benches"] for row in bench["figures"]}


def _series(figures: dict, pattern: str) -> list[tuple[int, dict]]:
    """(the number in the figure's name, its row) for names matching `pattern` (one group)."""
    found = [(int(m.group(1)), row) for name, row in figures.items()
             if (m := re.fullmatch(pattern, name))]
    return sorted(found, key=lambda item: item[0])


def _rpc_panel(ax, figures: dict) -> None:
    for rpc in RPCS:
        rows = _series(figures, rf"{rpc} p50, (\d+) clients")
        if not rows:
            continue
        n = [k for k, _ in rows]
        line, = ax.plot(n, [r["value"] for _, r in rows], "o-", label=rpc)
        ax.plot(n, [r["baseline"] for _, r in rows], "--", color=line.get_color(), alpha=0.6,
                label=f"echo, {rpc}'s size")
    ax.set(xscale="log", yscale="log", xlabel="concurrent clients", ylabel="p50 latency (ms)",
           title="Unary calls beside a bare echo")
    ax.set_xticks([1, 8, 32], ["1", "8", "32"])


def _event_panel(ax, figures: dict) -> None:
    rows = _series(figures, r"event latency p99, (\d+) subscriber\(s\)")
    n = [k for k, _ in rows]
    ax.plot(n, [r["value"] for _, r in rows], "o-", label="device server, p99")
    ax.plot(n, [r["baseline"] for _, r in rows], "o--", label="bare stream, p99")
    goals = [r["goal"] for _, r in rows if r.get("goal")]
    if goals:
        ax.axhline(goals[0], color="grey", lw=0.8, ls=":", label="goal")
    ax.set(xscale="log", xlabel="subscribers", ylabel="tag event latency (ms)",
           title="Events from the cycle to every subscriber")


def _stop_panel(ax, figures: dict) -> None:
    rows = [(name.split(", ", 1)[1], row) for name, row in figures.items()
            if name.startswith("stop latency p99, ")]
    ax.bar([label for label, _ in rows], [r["value"] for _, r in rows], color="tab:red")
    goals = [r["goal"] for _, r in rows if r.get("goal")]
    if goals:
        ax.axhline(goals[0], color="grey", lw=0.8, ls=":", label="goal: one cycle")
    ax.set(ylabel="StopMotion arriving to first decelerating cycle, p99 (ms)",
           title="Stops with the server idle and busy")
    ax.tick_params(axis="x", labelsize=7)


def _memory_panel(ax, figures: dict) -> None:
    row = figures.get("memory over time (server, cycle process, planning process)")
    if row is None:
        return
    t, server, cycle, planning = zip(*row["points"])
    ax.plot(t, server, label="device server")
    ax.plot(t, cycle, label="cycle process")
    ax.plot(t, planning, label="planning process")
    ax.set(xlabel="s (idle, then the load)", ylabel="resident memory (MB)",
           title="Memory through the soak", ylim=(0, max(server) * 1.2))


def plot_report(report: dict, path: Path) -> None:
    figures = _figures(report)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    for ax, panel in zip(axes.flat, (_rpc_panel, _event_panel, _stop_panel, _memory_panel)):
        panel(ax, figures)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    machine = report["machine"]
    fig.suptitle(f"LandScape-gRPC under load: {machine['date']}, {machine['cpu']} "
                 f"({machine['cores']} cores), commit {machine['commit']}"
                 f"{' (quick run)' if report.get('quick') else ''}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
