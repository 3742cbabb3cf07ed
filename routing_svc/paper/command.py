"""``routing-svc paper NAME [--out DIR] [--seeds N] [--quick] [--seed S]``.

Runs one of the paper's experiments (or ``all``) and writes, per experiment,
``DIR/NAME.json`` (parameters, key numbers and the plotted data) and
``DIR/NAME.png`` (drawn from that JSON). The default directory is
``docs/figures/paper``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from routing_svc.paper.result import ExperimentResult


@dataclass(frozen=True, slots=True)
class Experiment:
    """A named experiment: its module (imported when run), default seeds, description."""

    module: str
    seeds: int
    summary: str

    def run(self, *, seeds: int, quick: bool, seed: int) -> ExperimentResult:
        """Import the experiment's module and run it."""
        result: ExperimentResult = importlib.import_module(self.module).run(
            seeds=seeds, quick=quick, seed=seed
        )
        return result


EXPERIMENTS: dict[str, Experiment] = {
    "source-seeking": Experiment(
        "routing_svc.paper.source_seeking",
        100,
        "triangle formation vs single SPSA robot (II-A, IV-A)",
    ),
    "fading": Experiment(
        "routing_svc.paper.fading", 20, "relay chain under wireless fading (II-B, IV-B, Fig. 1)"
    ),
    "plane": Experiment(
        "routing_svc.paper.plane_coverage",
        10,
        "coverage vs MiniBatchKMeans, routing vs the p-median optimum",
    ),
    "heterogeneous": Experiment(
        "routing_svc.paper.heterogeneous", 20, "A/B vehicles pair up near (6, 6) (IV-C, Fig. 2)"
    ),
    "tracking": Experiment(
        "routing_svc.paper.tracking", 20, "decreasing vs asymptotically constant steps (III-D)"
    ),
}


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register the ``paper`` subcommand."""
    listing = "; ".join(f"{name}: {e.summary}" for name, e in EXPERIMENTS.items())
    parser = subparsers.add_parser(
        "paper",
        help="reproduce an experiment of the paper (PNG + JSON)",
        description=f"Experiments: {listing}.",
    )
    parser.add_argument("name", choices=[*EXPERIMENTS, "all"], help="experiment to run")
    parser.add_argument(
        "--out", type=Path, default=Path("docs/figures/paper"), help="output directory"
    )
    parser.add_argument(
        "--seeds", type=int, default=None, help="number of seeded runs (default: per experiment)"
    )
    parser.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    parser.add_argument(
        "--quick", action="store_true", help="shorter runs (for a smoke test; not the docs)"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the chosen experiment(s); print one JSON line per experiment."""
    names = list(EXPERIMENTS) if args.name == "all" else [args.name]
    if args.seeds is not None and args.seeds < 1:
        print("paper: --seeds must be >= 1", file=sys.stderr)
        return 2
    for name in names:
        experiment = EXPERIMENTS[name]
        seeds = args.seeds if args.seeds is not None else experiment.seeds
        started = time.perf_counter()
        result = experiment.run(seeds=seeds, quick=args.quick, seed=args.seed)
        seconds = time.perf_counter() - started
        write_outputs(result, args.out, command=command_line(name, args))
        report = {"experiment": name, "seconds": round(seconds, 1), **result.to_json()["summary"]}
        print(json.dumps(report))
    return 0


def command_line(name: str, args: argparse.Namespace) -> str:
    """The command that reproduces ``name`` with these options."""
    parts = ["routing-svc", "paper", name, "--out", str(args.out)]
    if args.seeds is not None:
        parts += ["--seeds", str(args.seeds)]
    if args.seed:
        parts += ["--seed", str(args.seed)]
    if args.quick:
        parts.append("--quick")
    return " ".join(parts)


def write_outputs(result: ExperimentResult, directory: Path, *, command: str) -> None:
    """Write ``NAME.json`` and ``NAME.png`` (the figure is drawn from the JSON)."""
    from routing_svc.paper.figures import draw, save_figure  # matplotlib only when drawing

    directory.mkdir(parents=True, exist_ok=True)
    record = {"command": command, **result.to_json()}
    text = json.dumps(record, indent=1, allow_nan=False)
    (directory / f"{result.name}.json").write_text(text + "\n", encoding="utf-8")
    stored = ExperimentResult.from_json(json.loads(text))
    save_figure(draw(stored), directory / f"{result.name}.png")


def main(argv: list[str] | None = None) -> int:
    """Run the subcommand on its own (``python -m routing_svc.paper.command``)."""
    parser = argparse.ArgumentParser(prog="routing-svc")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    code: int = args.run(args)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
