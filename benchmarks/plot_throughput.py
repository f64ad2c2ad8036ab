"""Throughput against batch size, MJX beside native MuJoCo, from throughput JSON files.

    python -m benchmarks.plot_throughput benchmarks/results_cpu.json \\
        benchmarks/results_gpu_h200.json benchmarks/results_gpu_h100.json \\
        --out benchmarks/throughput.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def machine_label(report: dict) -> str:
    """e.g. 'NVIDIA H200' or 'CPU, 2 cores'."""
    machine = report["machine"]
    kind = machine.get("device_kind", "cpu")
    return f"CPU, {machine['cpu_count']} cores" if kind.lower() == "cpu" else kind


def plot(reports: list[dict], out: Path) -> None:
    """One line per machine for MJX and one for native MuJoCo on that machine's cores."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, report in enumerate(reports):
        results = sorted(report["results"], key=lambda r: r["batch"])
        if not results:
            continue
        batch = [r["batch"] for r in results]
        color = f"C{i}"
        label = machine_label(report)
        ax.plot(batch, [r["physics_steps_per_s"] for r in results], "o-", color=color,
                label=f"MJX on {label}")
        threads = results[0]["native"]["nthread"]
        ax.plot(batch, [r["native"]["physics_steps_per_s"] for r in results], "s--",
                color=color, alpha=0.6, label=f"native MuJoCo, same machine, {threads} threads")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("batch size (parallel environments)")
    ax.set_ylabel("physics steps / s")
    ax.set_title("Hand-pair scene: MJX vs native MuJoCo (same starts and set-points)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path, help="JSON files of benchmarks.throughput")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/throughput.png"))
    args = parser.parse_args(argv)
    reports = []
    for path in args.results:
        try:
            report = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise SystemExit(f"{path}: not a readable throughput JSON ({err})") from None
        if not isinstance(report, dict) or not {"machine", "results"} <= report.keys():
            raise SystemExit(f"{path}: expected the JSON of benchmarks.throughput "
                             "(keys 'machine' and 'results')")
        reports.append(report)
    plot(reports, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
