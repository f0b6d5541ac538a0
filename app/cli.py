"""The installed `l3mvn` script: the library's commands plus `serve`, the dashboard (its arguments and run)."""

from __future__ import annotations

import argparse
import sys
import time

from l3mvn.core.errors import L3MVNError, one_line

REPORT_HELP = "one self-contained HTML page over eval result files: tables with intervals, charts, videos"


def _typed(kind: type, flag: str):
    """An argparse type reading ``flag`` as ``--set`` reads numbers (ASCII digits, finite)."""
    from l3mvn.core.config import number

    def parse(raw: str):
        try:
            return number(raw, kind, flag)
        except L3MVNError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"{flag} ")) from None

    parse.__name__ = kind.__name__  # argparse names the type in its message
    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from l3mvn.run.registry import policy_names
    from l3mvn_studio.origin import ALLOW_ORIGIN_FLAG

    parser.add_argument("--dataset", default=None, help="SemExp-format dataset directory (default: procedural houses)")
    parser.add_argument(
        "--scenes",
        default=None,
        metavar="DIR",
        help="scan root of a habitat ObjectNav --dataset (e.g. data/scene_datasets)",
    )
    parser.add_argument("--split", default="val", help="split name inside --dataset (default: val)")
    parser.add_argument(
        "--houses", type=_typed(int, "--houses"), default=3, help="procedural houses when no --dataset (default 3)"
    )
    parser.add_argument(
        "--episodes-per-house",
        type=_typed(int, "--episodes-per-house"),
        default=5,
        help="procedural episodes per house (default 5)",
    )
    parser.add_argument(
        "--seed", type=_typed(int, "--seed"), default=0, help="seed for procedural houses, episodes and policies"
    )
    parser.add_argument(
        "--policy",
        choices=policy_names(),
        default="l3mvn-zs",
        help="policy selected when the page opens (changeable in the page)",
    )
    parser.add_argument(
        "--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1; anything else exposes the controls)"
    )
    parser.add_argument(
        ALLOW_ORIGIN_FLAG,
        action="append",
        default=[],
        metavar="ORIGIN",
        dest="allow_origin",
        help="also accept pages served from ORIGIN (scheme://host[:port], e.g. a reverse "
        "proxy's https://studio.example.com); repeatable. By default only "
        "http://127.0.0.1:PORT, http://localhost:PORT and http://HOST:PORT may connect",
    )
    parser.add_argument("--port", type=_typed(int, "--port"), default=8080, help="port (default 8080)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.FIELD=VALUE",
        help="override any config field, as for `l3mvn eval` (`l3mvn config` lists them)",
    )
    parser.add_argument(
        "--speed", type=_typed(float, "--speed"), default=4.0, help="steps per second while running (default 4)"
    )
    parser.add_argument("--record", action="store_true", help="record each episode to recordings/*.rrd")
    parser.add_argument(
        "--record-dir",
        default=None,
        metavar="DIR",
        help="where --record and the Results panel's re-runs write (default: recordings/ for "
        "--record, reruns/ beside --recordings for re-runs; never the eval's recordings)",
    )
    parser.add_argument(
        "--results", default=None, metavar="DIR", help="add a Results panel over the eval result files (*.jsonl) in DIR"
    )
    parser.add_argument(
        "--recordings",
        default=None,
        metavar="DIR",
        help="where the Results panel reads the eval's recordings (default recordings/, "
        "where `l3mvn eval --record` writes); never written to",
    )


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C, SIGTERM or SIGHUP, then stop the worker, recorder, view and web server (0).

    A bad flag, host or port, or a port in use, is one line on stderr and status 2, before anything
    is served.
    """
    from l3mvn.core.config import Config, TaskConfig, override
    from l3mvn.run.serving import interrupt_on_stop_signals
    from l3mvn.world.datasets.objectnav import dataset_rule
    from l3mvn_studio.origin import ALLOW_ORIGIN_FLAG, LOOPBACK_HOSTS
    from l3mvn_studio.server import start_dashboard
    from l3mvn_studio.session_worker import check_speed

    with interrupt_on_stop_signals():
        try:
            check_speed(args.speed)
            # The dataset's own success rule (HM3D / MP3D view points, else SemExp's), as `l3mvn eval` takes it.
            cfg = Config(task=TaskConfig(success_rule=dataset_rule(args.dataset, args.split)))
            dash = start_dashboard(
                cfg=override(cfg, args.set),
                dataset=args.dataset,
                split=args.split,
                scenes_dir=args.scenes,
                policy=args.policy,
                host=args.host,
                port=args.port,
                houses=args.houses,
                episodes_per_house=args.episodes_per_house,
                seed=args.seed,
                steps_per_second=args.speed,
                record=args.record,
                record_dir=args.record_dir,
                allow_origins=args.allow_origin,
                results_dir=args.results,
                recordings_dir=args.recordings,
            )
        except L3MVNError as exc:
            print(f"error: {one_line(exc)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("interrupted while starting; nothing was served", file=sys.stderr)
            return 130
        _serve_until_stopped(dash, args.host, args.port, ALLOW_ORIGIN_FLAG, LOOPBACK_HOSTS)
    return 0


def _serve_until_stopped(dash, host: str, port: int, allow_flag: str, loopback: tuple[str, ...]) -> None:
    """Say where it serves, wait for Ctrl-C, SIGTERM or SIGHUP (each a KeyboardInterrupt here), then
    stop the dashboard. The announcement is inside the guarded block: a signal that arrives right
    after the URL line (a supervisor that starts and stops at once) still stops everything."""
    try:
        if host not in loopback:
            print(
                f"warning: serving on {host}: anyone who can reach it can drive the dashboard; "
                f"a browser that opens it by another name needs {allow_flag} http://NAME:{port}",
                file=sys.stderr,
            )
        print(f"L3MVN Studio dashboard: {dash.url}  (Ctrl-C to stop)", flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("stopping", file=sys.stderr)
    finally:
        dash.stop()


def serve_main(argv: list[str] | None = None) -> int:
    """``l3mvn serve`` on its own (``argv`` without the subcommand)."""
    parser = argparse.ArgumentParser(prog="l3mvn serve", description="live web dashboard")
    add_arguments(parser)
    return run(parser.parse_args(argv))


def main(argv: list[str] | None = None) -> int:
    """The installed ``l3mvn`` script: the library's commands and the dashboard's ``serve``."""
    from l3mvn.run.cli import Command
    from l3mvn.run.cli import main as l3mvn_main

    return l3mvn_main(
        argv,
        extra={
            "serve": Command("the live web dashboard (viser)", add_arguments, run),
            "report": Command.lazy(REPORT_HELP, "l3mvn_studio.report", "add_report_arguments", "run_report"),
        },
    )


if __name__ == "__main__":
    sys.exit(main())
