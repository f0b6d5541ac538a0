"""``l3mvn serve``: arguments and entry point (l3mvn/cli.py wires the subcommand to these two)."""

from __future__ import annotations

import argparse
import sys
import time

from l3mvn.errors import L3MVNError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from l3mvn.policies import POLICY_NAMES

    parser.add_argument("--dataset", default=None, help="SemExp-format dataset directory (default: procedural houses)")
    parser.add_argument("--split", default="val", help="split name inside --dataset (default: val)")
    parser.add_argument("--houses", type=int, default=3, help="procedural houses when no --dataset (default 3)")
    parser.add_argument("--episodes-per-house", type=int, default=5, help="procedural episodes per house (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed for procedural houses, episodes and policies")
    parser.add_argument("--policy", choices=POLICY_NAMES, default="oracle" if "l3mvn-zs" not in POLICY_NAMES
                        else "l3mvn-zs", help="policy selected when the page opens (changeable in the page)")
    parser.add_argument("--host", default="127.0.0.1",
                        help="interface to bind (default 127.0.0.1; anything else exposes the controls)")
    parser.add_argument("--port", type=int, default=8080, help="port (default 8080)")
    parser.add_argument("--speed", type=float, default=4.0, help="steps per second while running (default 4)")
    parser.add_argument("--record", action="store_true", help="record each episode to recordings/*.rrd")
    parser.add_argument("--record-dir", default="recordings", help="where --record writes (default recordings/)")


def run(args: argparse.Namespace) -> int:
    from app.server import start_dashboard

    try:
        dash = start_dashboard(dataset=args.dataset, split=args.split, policy=args.policy, host=args.host,
                               port=args.port, houses=args.houses, episodes_per_house=args.episodes_per_house,
                               seed=args.seed, steps_per_second=args.speed, record=args.record,
                               record_dir=args.record_dir)
    except L3MVNError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: serving on {args.host}: anyone who can reach it can drive the dashboard", file=sys.stderr)
    print(f"L3MVN Studio dashboard: {dash.url}  (Ctrl-C to stop)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("stopping", file=sys.stderr)
    finally:
        dash.stop()
    return 0


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry (``python -m app.cli``) until ``l3mvn serve`` is wired."""
    parser = argparse.ArgumentParser(prog="l3mvn serve", description="live web dashboard")
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
