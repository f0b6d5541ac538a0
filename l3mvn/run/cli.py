"""``l3mvn`` command line: eval, scenes, episodes, render, config.

Every user error is one line on stderr (``error: ...``) and exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from l3mvn.core.config import SUCCESS_RULES, Config, PolicyConfig, TaskConfig, config_dict, config_hash, override
from l3mvn.core.config.policy import DEFAULT_HEAD, HEAD_KINDS, LLM_PROMPTS, MAP_HEAD, SELECTIONS
from l3mvn.core.config.sim import BACKENDS
from l3mvn.core.config.task import VIEW_POINT_RULES
from l3mvn.core.errors import L3MVNError, one_line


def frame_size(text: str) -> tuple[int, int]:
    """``HxW`` as (height, width): the one reading of a frame-size flag (the CLI and the benches)."""
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"frame size must look like 120x160, got {text!r}") from None
    if h <= 0 or w <= 0:
        raise argparse.ArgumentTypeError(f"frame size must be positive, got {text!r}")
    return h, w


def _positive(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a number >= 1, got {v}")
    return v


def _add_sim_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--rule",
        choices=SUCCESS_RULES,
        default=None,
        help="success rule (default: the dataset's: habitat's view-point rule for HM3D / MP3D episode "
        "files, else SemExp's Gibson rule, as in the paper's table)",
    )
    p.add_argument(
        "--frame",
        type=frame_size,
        default=None,
        metavar="HxW",
        help="render size (default 480x640; 120x160 is what the mapper consumes)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.FIELD=VALUE",
        help="override any config field, e.g. --set sim.max_steps=300 or --set agent.replan_every=5 "
        "(`l3mvn config` lists them all)",
    )


def _add_source_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--dataset",
        default=None,
        help="SemExp-format or habitat ObjectNav (objectnav_hm3d v1/v2, objectnav_mp3d) dataset directory "
        "(default: procedural houses)",
    )
    p.add_argument(
        "--scenes",
        default=None,
        metavar="DIR",
        help="scan root of a habitat ObjectNav --dataset (e.g. data/scene_datasets)",
    )
    p.add_argument("--split", default="val", help="split name inside --dataset (default: val)")
    p.add_argument("--houses", type=_positive, default=5, help="procedural houses when no --dataset (default 5)")
    p.add_argument("--seed", type=int, default=0, help="seed for procedural houses, episodes and policies")


def _config(args: argparse.Namespace, policy: PolicyConfig | None = None) -> Config:
    """The config tree from the flags: ``--rule``, ``--frame`` and the policy flags first, then every
    ``--set`` on top (so a ``--set`` wins over the flag it repeats)."""
    rule = args.rule
    if rule is None:
        from l3mvn.world.datasets.objectnav import dataset_rule

        rule = dataset_rule(getattr(args, "dataset", None), getattr(args, "split", "val"))
    cfg = Config(task=TaskConfig(success_rule=rule), policy=policy or PolicyConfig())
    if args.frame:
        cfg = cfg.with_frame(*args.frame)
    backend = [f"sim.backend={args.sim}"] if getattr(args, "sim", None) else []
    if getattr(args, "habitat_python", None):
        backend.append(f"sim.habitat_python={args.habitat_python}")
    cfg = override(cfg, backend + args.set)
    if cfg.sim.backend == "habitat":
        from l3mvn.world.sim.habitat_bridge import habitat_command

        habitat_command(cfg.sim.habitat_python)  # a bad path is one line here, not an error per episode
    cfg.agent.downsample_factor(cfg.sim.frame_height, cfg.sim.frame_width)
    return cfg


@dataclass(frozen=True)
class Command:
    """A subcommand whose arguments and run live beside what it drives, or above the library (the
    dashboard's ``serve``), so the library never imports the application that uses it."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]

    @classmethod
    def lazy(cls, help: str, module: str, add_arguments: str, run: str) -> Command:
        """A command whose module is imported only when it is the command asked for (torch, rerun
        and the dashboard take seconds to import; ``l3mvn eval`` needs none of them)."""

        def member(name: str) -> Callable:
            return lambda arg: getattr(importlib.import_module(module), name)(arg)

        return cls(help, member(add_arguments), member(run))


def _library_commands() -> dict[str, Command]:
    """Commands whose arguments and run live beside what they drive."""
    return {
        "export": Command.lazy(
            "write an MP4 (--gif: and a GIF) of a recorded episode, or of the (failed) episodes of a result file",
            "l3mvn.run.eval.result_videos",
            "add_export_arguments",
            "run_export",
        ),
        "export-hm3d": Command.lazy(
            "export procedural houses as scans in HM3D's layout, with an objectnav_hm3d_v2 "
            "episode file (to run them here and on habitat-sim)",
            "l3mvn.world.datasets.hm3d_export",
            "add_export_arguments",
            "run_export",
        ),
        "replay": Command.lazy(
            "open a rerun recording (.rrd) in the rerun viewer",
            "l3mvn.run.recording",
            "add_replay_arguments",
            "run_replay",
        ),
        "poni": Command.lazy(
            "the PONI policy's potential network: train it from full house maps and walks, or show a checkpoint",
            "l3mvn.run.potentials.train",
            "add_arguments",
            "run",
        ),
    }


def _command_in(argv: list[str]) -> str | None:
    """The subcommand named on the command line (its first word), or None (``--help``, nothing)."""
    return argv[0] if argv and not argv[0].startswith("-") else None


def build_parser(extra: dict[str, Command] | None = None, only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``only``, the contributed commands other than that one are
    listed by name and help without their arguments (building those imports what they drive)."""
    from l3mvn.run.registry import policy_names

    parser = argparse.ArgumentParser(prog="l3mvn", description="L3MVN Studio: language-guided ObjectNav")
    sub = parser.add_subparsers(dest="command", required=True)

    ev = sub.add_parser("eval", help="run episodes with a policy and report SR / SPL / DTG")
    _add_source_args(ev)
    _add_sim_args(ev)
    ev.add_argument(
        "--policy", required=True, choices=policy_names(driven=False), help="(teleop is driven by hand: `l3mvn serve`)"
    )
    ev.add_argument("--episodes", type=_positive, default=None, help="run only the first N episodes")
    ev.add_argument("--episodes-per-house", type=_positive, default=10, help="procedural episodes per house")
    ev.add_argument("--out", default=None, help="append one JSON line per finished episode here")
    ev.add_argument("--resume", action="store_true", help="skip episodes already in --out (same policy and config)")
    ev.add_argument("--json", action="store_true", help="print the summary as one JSON object on the last line")
    ev.add_argument(
        "--workers",
        type=_positive,
        default=None,
        help="episodes run in parallel (default: 1 locally, one per CPU on Ray)",
    )
    ev.add_argument(
        "--backend",
        choices=["local", "ray"],
        default="local",
        help="local worker processes, or Ray actors (pip install 'l3mvn[distributed]')",
    )
    ev.add_argument(
        "--address",
        default=None,
        help="Ray cluster to join (auto, HOST:PORT, ray://HOST:10001); default: a private local Ray",
    )
    ev.add_argument("--scorer", default=None, help="language policies: scorer instead of the policy's default")
    ev.add_argument(
        "--selection",
        choices=SELECTIONS,
        default="paper",
        help="language policies: the paper's bound rule, the official code's thresholds, or expected "
        "(least cost-utility metres + the frontier head's expected metres; needs --head "
        "frontiers or frontiers-bag)",
    )
    ev.add_argument(
        "--head",
        default=None,
        metavar="KIND|FILE",
        help=f"feed-forward scorer: head trained on frontiers of house maps or on room lists ({', '.join(HEAD_KINDS)}; "
        f"-bag: the same on a bag of objects, without the language model; default {DEFAULT_HEAD}); {MAP_HEAD}: "
        "PONI's potentials from the partial map corrected by the words of each frontier's window; or a head "
        "file from `l3mvn train-head` or `l3mvn poni train-language`",
    )
    ev.add_argument(
        "--embedder",
        default=None,
        help="feed-forward scorer: the sentence embedder (Emb(W)) whose head to read: minilm (default) or an LLM "
        "(smollm2-135m, gemma3-270m, a .gguf file); a head file reads the embedder it was trained on",
    )
    ev.add_argument(
        "--llm",
        default=PolicyConfig.llm,
        metavar="MODEL",
        help=f"scorer llm: a named model (`l3mvn language models` lists them) or a .gguf file "
        f"(default {PolicyConfig.llm})",
    )
    ev.add_argument(
        "--prompt",
        choices=LLM_PROMPTS,
        default=PolicyConfig.llm_prompt,
        help="scorer llm: the paper's query scored by log p(W), or the contrastive prompt (worked examples, "
        "the goal's own prior subtracted)",
    )
    ev.add_argument(
        "--seg-noise",
        type=float,
        default=0.0,
        metavar="P",
        help="perception errors: per frame and category, miss / mislabel with probability P",
    )
    ev.add_argument(
        "--sim",
        choices=BACKENDS,
        default=None,
        help="who moves and renders: builtin (default) or habitat (habitat-sim in --habitat-python, "
        "scans only: --dataset with --scenes); same as --set sim.backend=...",
    )
    ev.add_argument(
        "--habitat-python",
        default=None,
        metavar="PATH",
        help="the python of the environment that has habitat-sim (`make habitat` builds one into "
        "~/.cache/l3mvn/habitat/python)",
    )
    ev.add_argument("--record", action="store_true", help="write a rerun recording per episode to --record-dir")
    ev.add_argument("--record-dir", default="recordings", help="where --record writes (default recordings/)")
    ev.add_argument(
        "--video",
        metavar="DIR",
        default=None,
        help="also write an MP4 per episode here, named by outcome (implies --record)",
    )

    cr = sub.add_parser(
        "compare-results",
        help="two result files on the same episodes: per-episode differences in SR and SPL with 95%% intervals",
    )
    cr.add_argument("a", help="result file A (.jsonl)")
    cr.add_argument("b", help="result file B (.jsonl): differences are B - A")
    cr.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")

    tb = sub.add_parser(
        "table", help="the paper's Table I (paper-1) or Table II (paper-2): every row we have, run, beside the paper's"
    )
    tb.add_argument("name", choices=["paper-1", "paper-2"])
    _add_source_args(tb)
    _add_sim_args(tb)
    tb.add_argument(
        "--results",
        default="results/tables",
        metavar="DIR",
        help="one result file per row here, resumed by a second call (default results/tables)",
    )
    tb.add_argument("--episodes", type=_positive, default=None, help="only the first N episodes of each row")
    tb.add_argument("--episodes-per-house", type=_positive, default=10, help="procedural episodes per house")
    tb.add_argument("--workers", type=_positive, default=1, help="episodes in parallel (default 1)")
    tb.add_argument(
        "--seg-noise",
        type=float,
        default=0.0,
        metavar="P",
        help="paper-2: perception errors for the rows the paper ran with a trained detector (default 0)",
    )

    sc = sub.add_parser("scenes", help="list the scenes and floors of a dataset split, or audit them")
    sc.add_argument(
        "action",
        nargs="?",
        choices=["list", "audit"],
        default="list",
        help="list (default), or audit: can every goal object be confirmed from its success region",
    )
    _add_source_args(sc)
    sc.add_argument("--rule", choices=SUCCESS_RULES, default="semexp", help="audit: success rule")
    sc.add_argument("--frame", default=None, metavar="HxW", help="audit: render size (default 480x640)")
    sc.add_argument(
        "--set", action="append", default=[], metavar="SECTION.FIELD=VALUE", help="audit: override a config field"
    )
    sc.add_argument("--scene", default=None, help="audit: only this scene")
    sc.add_argument("--workers", type=_positive, default=2, help="audit: floors audited in parallel (default 2)")
    sc.add_argument("--json", action="store_true", help="audit: print the JSON report instead of the table")
    sc.add_argument(
        "--out", default=None, help="audit: write audit.json and a diagnostic PNG per failing instance here"
    )
    sc.add_argument("--all-pngs", action="store_true", help="audit: a PNG for every instance, not only failing ones")

    epi = sub.add_parser("episodes", help="episode files")
    epi_sub = epi.add_subparsers(dest="episodes_command", required=True)
    gen = epi_sub.add_parser("generate", help="generate episodes for every scene of a split")
    _add_source_args(gen)
    gen.add_argument("--out", required=True, help="dataset directory to write <split>/content/*_episodes.json.gz into")
    gen.add_argument("--per-scene", type=_positive, default=50, help="episodes per scene floor (default 50)")
    gen.add_argument("--min-distance", type=float, default=1.0, help="min geodesic start distance, m")
    gen.add_argument("--max-distance", type=float, default=30.0, help="max geodesic start distance, m")

    for name, command in {**_library_commands(), **(extra or {})}.items():
        contributed = sub.add_parser(name, help=command.help)
        if only is None or only == name:
            command.add_arguments(contributed)

    lang = sub.add_parser("language", help="co-occurrence statistics behind the language prior")
    lang_sub = lang.add_subparsers(dest="language_command", required=True)
    st = lang_sub.add_parser("stats", help="print p(goal | object), entropy and the informative list")
    st.add_argument("--min-rooms", type=_positive, default=1, help="hide objects seen in fewer rooms")
    lang_sub.add_parser("models", help="the LLMs the llm scorer can load: installed or not, license, source")
    bs = lang_sub.add_parser("build-stats", help="recompute the shipped co-occurrence JSON from room data")
    bs.add_argument("--gibson-rooms", default=None, help="gibson_3dsg_rooms.jsonl (default: ../shared when present)")
    bs.add_argument("--out", default=None, help="where to write (default: the shipped file)")
    fd = lang_sub.add_parser(
        "frontier-data",
        help="frontiers an agent chose among on house maps, labelled with "
        "the ground-truth metres to every goal (for train-head)",
    )
    if only in (None, "language"):
        from l3mvn.run.eval.frontier_data import add_arguments as add_frontier_data_arguments

        add_frontier_data_arguments(fd)
    th = sub.add_parser("train-head", help="train the feed-forward language head (split by house or building)")
    th.add_argument(
        "--head",
        choices=HEAD_KINDS,
        default="frontiers",
        help="frontiers: on --data from `language frontier-data`; rooms: the paper's room lists; "
        "-bag: the same on a bag of objects, without the language model",
    )
    th.add_argument("--data", nargs="+", default=None, help="--head frontiers: frontier-data file(s)")
    th.add_argument(
        "--model",
        default="minilm",
        help="sentence embedder: minilm (shipped), an LLM (smollm2-135m, gemma3-270m, a .gguf file) or a HF name/path",
    )
    th.add_argument("--out", default=None, help="where to save the head (default: the shipped file for minilm)")
    th.add_argument("--gibson-rooms", default=None)
    th.add_argument("--epochs", type=_positive, default=None, help="default: 80 (frontiers), 60 (rooms)")
    th.add_argument("--seed", type=int, default=0)

    cf = sub.add_parser("config", help="every setting of the config tree, with --set applied, and its hash")
    _add_sim_args(cf)
    cf.add_argument("--json", action="store_true", help="print the tree as JSON")

    rd = sub.add_parser("render", help="write RGB | depth | semantic of one view side by side to a PNG")
    _add_source_args(rd)
    _add_sim_args(rd)
    rd.add_argument("--scene", default=None, help="scene name (default: the first)")
    rd.add_argument("--floor", type=int, default=0)
    rd.add_argument(
        "--pose",
        default=None,
        metavar="X,Y,HEADING_DEG",
        help="camera pose in metres/degrees (default: a random navigable pose)",
    )
    rd.add_argument("--out", default="frame.png")
    return parser


def main(argv: list[str] | None = None, extra: dict[str, Command] | None = None) -> int:
    """``l3mvn``: the library's commands plus ``extra`` ones (the installed script adds ``serve``)."""
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(extra, only=_command_in(argv))
    args = parser.parse_args(argv)
    try:
        commands = {**_library_commands(), **(extra or {})}
        if args.command in commands:
            return commands[args.command].run(args)
        if args.command == "eval":
            return _cmd_eval(args)
        if args.command == "compare-results":
            from l3mvn.run.eval.paired import compare_results, format_pairing

            print(format_pairing(compare_results(args.a, args.b, seed=args.seed)))
            return 0
        if args.command == "table":
            return _cmd_table(args)
        if args.command == "scenes":
            return _cmd_audit(args) if args.action == "audit" else _cmd_scenes(args)
        if args.command == "episodes":
            return _cmd_generate(args)
        if args.command == "render":
            return _cmd_render(args)
        if args.command == "config":
            return _cmd_config(args)
        if args.command == "language":
            return _cmd_language(args)
        if args.command == "train-head":
            return _cmd_train_head(args)
    except L3MVNError as exc:
        print(f"error: {one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:  # a disk or path failure no writer above turned into its own words
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}".replace("\n", "\\n"), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: finished episodes are saved", file=sys.stderr)
        return 130
    parser.error(f"unknown command {args.command!r}")
    return 2


def _scenes(args: argparse.Namespace, cfg: Config | None = None):
    """(source, scenes) of the source flags; a habitat ObjectNav dataset loads its scans (``cfg``'s body)."""
    from l3mvn.world.datasets import load_episode_set
    from l3mvn.world.datasets.objectnav import is_objectnav
    from l3mvn.world.scenes.procedural import procedural_split
    from l3mvn.world.scenes.semexp import load_split

    if args.dataset is None:
        if args.scenes is not None:
            raise L3MVNError("--scenes is the scan root of an ObjectNav dataset: give --dataset too")
        return "procedural", procedural_split(args.houses, args.seed)
    if args.scenes is not None or is_objectnav(args.dataset, args.split):
        eset = load_episode_set(args.dataset, args.split, cfg=cfg, scenes_dir=args.scenes)
        return f"{args.dataset} ({eset.format})", eset.scenes
    return args.dataset, load_split(args.dataset, args.split)


def _cmd_scenes(args: argparse.Namespace) -> int:
    given = [
        flag
        for flag, value in (
            ("--scene", args.scene),
            ("--frame", args.frame),
            ("--out", args.out),
            ("--json", args.json),
            ("--all-pngs", args.all_pngs),
            ("--set", args.set),
        )
        if value
    ]
    if given:
        raise L3MVNError(f"{', '.join(given)}: only for 'l3mvn scenes audit'")
    source, scenes = _scenes(args)
    print(f"{source} / {args.split if args.dataset else '-'}: {len(scenes)} scenes")
    print(f"{'scene':<22}{'floor':>6}{'size (m)':>14}{'navigable m2':>14}  goals present")
    for name in sorted(scenes):
        for floor, s in sorted(scenes[name].items()):
            h, w = s.shape
            size = f"{h * s.resolution_m:.1f}x{w * s.resolution_m:.1f}"
            area = s.navigable.sum() * s.resolution_m**2
            print(f"{name:<22}{floor:>6}{size:>14}{area:>14.1f}  {', '.join(s.present_goals())}")
    return 0


def _cmd_audit(args: argparse.Namespace) -> int:
    from l3mvn.core.writing import write_file
    from l3mvn.run.audit import audit_scenes, format_report, load_split_for_audit
    from l3mvn.world.episode import Episode

    if args.frame is not None:
        try:
            args.frame = frame_size(args.frame)
        except argparse.ArgumentTypeError as exc:
            raise L3MVNError(f"--frame: {exc}") from None
    cfg = _config(args)
    if args.dataset is None:
        source, split = "procedural", "-"
        episodes: list[Episode] = []
        _, scenes = _scenes(args)
        if args.scene is not None:
            if args.scene not in scenes:
                raise L3MVNError(f"unknown scene {args.scene!r}; available: {', '.join(sorted(scenes))}")
            scenes = {args.scene: scenes[args.scene]}
    else:
        source, split = args.dataset, args.split
        scenes, episodes = load_split_for_audit(args.dataset, args.split, args.scene)
    with _progress_floors(sum(len(f) for f in scenes.values())) as bar:

        def progress(floor) -> None:
            bar.update(1)
            bar.set_postfix_str(floor.key)

        report = audit_scenes(
            scenes,
            cfg,
            episodes,
            workers=args.workers,
            out_dir=args.out,
            all_pngs=args.all_pngs,
            source=source,
            split=split,
            progress=progress,
        )
    data = report.to_json()
    if args.out:
        path = write_file(Path(args.out) / "audit.json", json.dumps(data, indent=1), "the audit report")
        print(f"wrote {path}", file=sys.stderr)
    print(json.dumps(data) if args.json else format_report(report))
    return 0


def _progress_floors(total: int):
    from tqdm import tqdm

    return tqdm(total=total, unit="floor", file=sys.stderr, dynamic_ncols=True, mininterval=1.0)


def _cmd_generate(args: argparse.Namespace) -> int:
    from l3mvn.core.paths import plain_name
    from l3mvn.world.episode import Episode
    from l3mvn.world.episodes import episode_file, generate_episodes, write_episode_file
    from l3mvn.world.scenes.semexp import info_path, save_split, to_semexp_channels

    plain_name(args.split, "--split", "val")  # a folder under --out: it must not climb out of it
    _, scenes = _scenes(args)
    out = Path(args.out)
    split_out = out / args.split
    try:
        split_out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise L3MVNError(f"--out {out}: cannot create {split_out} ({exc.strerror or exc})") from None
    maps = split_out / f"{args.split}_info.pbz2"
    if args.dataset is None:
        save_split(out, args.split, [to_semexp_channels(f) for fl in scenes.values() for f in fl.values()])
    elif not maps.exists():
        src = info_path(args.dataset, args.split).resolve()
        if src != maps.resolve():
            maps.symlink_to(src)
    total = 0
    for name in sorted(scenes):
        episodes: list[Episode] = []
        for _, scene in sorted(scenes[name].items()):
            episodes += generate_episodes(
                scene,
                args.per_scene,
                seed=args.seed,
                first_id=len(episodes),
                min_distance_m=args.min_distance,
                max_distance_m=args.max_distance,
            )
        write_episode_file(episode_file(out, args.split, name), episodes, scenes[name])
        total += len(episodes)
    print(f"wrote {total} episodes for {len(scenes)} scenes to {split_out / 'content'}")
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    """Check the flags, run the evaluation (``l3mvn.run.eval.evaluation``), print the summary of this
    run's valid rows (``--resume``: the file's too)."""
    from l3mvn.core.json_values import json_safe
    from l3mvn.core.writing import make_folder
    from l3mvn.run.eval.evaluation import evaluate
    from l3mvn.run.eval.job import EvalJob
    from l3mvn.run.eval.metrics import format_summary, summarize
    from l3mvn.run.eval.results import check_resumable
    from l3mvn.run.registry import scorer_choice

    if args.address and args.backend != "ray":
        raise L3MVNError("--address joins a Ray cluster: add --backend ray")
    if args.scorer is not None:
        from l3mvn.agent.language import scorer_names

        if args.scorer not in scorer_names():
            raise L3MVNError(f"unknown scorer {args.scorer!r}; valid scorers: {', '.join(scorer_names())}")
    cfg = _config(
        args,
        PolicyConfig(
            scorer=args.scorer,
            selection=args.selection,
            seg_noise=args.seg_noise,
            head=args.head,
            embedder=args.embedder,
            llm=args.llm,
            llm_prompt=args.prompt,
        ),
    )
    if cfg.sim.backend == "habitat" and args.scenes is None:
        raise L3MVNError(
            "--sim habitat runs scans: give --dataset with a habitat ObjectNav dataset and --scenes "
            "with its scan root (`l3mvn export-hm3d` writes one from a procedural house)"
        )
    check_resumable(args.out, args.resume)
    if fallback := scorer_choice(args.policy, cfg.policy)[1]:
        print(f"note: {fallback}", file=sys.stderr)
    job = EvalJob.create(
        args.dataset,
        args.split,
        houses=args.houses,
        episodes_per_house=args.episodes_per_house,
        seed=args.seed,
        config=cfg,
        policy=args.policy,
        record_dir=args.record_dir if args.record or args.video else None,
        scenes=args.scenes,
    )
    eset = job.load()
    if cfg.task.success_rule in VIEW_POINT_RULES:
        from l3mvn.world.datasets.objectnav import geodesic_report

        print(geodesic_report(eset, cfg), file=sys.stderr)
    episodes = eset.episodes[: args.episodes] if args.episodes else eset.episodes
    if args.video:
        make_folder(args.video, "--video")
    run = evaluate(
        job,
        episodes,
        out=args.out,
        resume=args.resume,
        backend=args.backend,
        workers=args.workers,
        address=args.address,
        video_dir=args.video,
        stream=sys.stderr,
    )
    if run.errors:
        print(
            f"{run.errors} episodes failed (error rows in {args.out or 'the log above'}; --resume retries them)",
            file=sys.stderr,
        )
    if not run.rows:
        if run.interrupted:
            raise KeyboardInterrupt
        raise L3MVNError("no episodes were run")
    if run.interrupted:
        print(
            f"interrupted: summary of the {len(run.rows)} of {len(episodes)} episodes finished "
            f"(saved in {args.out or 'no file: add --out'}; --resume runs the rest)",
            file=sys.stderr,
        )
    summary = summarize(list(run.rows.values()))
    summary["dataset"] = {"name": eset.name, "split": eset.split, "format": eset.format}
    print(f"dataset: {eset.name}/{eset.split}, format {eset.format}")
    print(format_summary(summary))
    if args.json:
        print(json.dumps(json_safe(summary), sort_keys=True))
    if run.unwritten and not run.interrupted:
        raise L3MVNError(
            f"{len(run.unwritten)} recordings or videos were not written whole, the results are kept "
            f"(first: {run.unwritten[0]})"
        )
    return 130 if run.interrupted else 0


def _cmd_table(args: argparse.Namespace) -> int:
    from l3mvn.core.writing import make_folder
    from l3mvn.run.eval.paper_tables import TableRun, run_table

    make_folder(args.results, "--results")
    run = TableRun(
        args.dataset,
        args.split,
        _config(args),
        Path(args.results),
        episodes=args.episodes,
        workers=args.workers,
        seg_noise=args.seg_noise,
        scenes=args.scenes,
        houses=args.houses,
        episodes_per_house=args.episodes_per_house,
        seed=args.seed,
    )
    print(run_table(args.name, run, stream=sys.stderr))
    return 0


def _cmd_language(args: argparse.Namespace) -> int:
    from l3mvn.agent.language import build_stats_file, load_stats, stats_table

    if args.language_command == "stats":
        print(stats_table(load_stats(), min_rooms=args.min_rooms))
        return 0
    if args.language_command == "frontier-data":
        from l3mvn.run.eval.frontier_data import run

        return run(args)
    if args.language_command == "models":
        from l3mvn.agent.language.llm import LLM_MODELS, llm_problem

        for name, source in LLM_MODELS.items():
            problem = llm_problem(name)
            state = "installed" if problem is None else f"not installed: {source.pip}"
            print(
                f"{name}: {state}; license {source.license}; source {source.source}; "
                f"card l3mvn/data/models/{source.card}"
            )
        return 0
    kwargs = {"gibson_rooms": args.gibson_rooms}
    if args.out:
        kwargs["out"] = args.out
    stats = build_stats_file(**kwargs)
    print(stats_table(stats))
    return 0


def _cmd_train_head(args: argparse.Namespace) -> int:
    from l3mvn.agent.language import train_any_head

    metrics = train_any_head(
        args.head,
        data=args.data,
        model=args.model,
        out=args.out,
        gibson_rooms=args.gibson_rooms,
        epochs=args.epochs,
        seed=args.seed,
    )
    print(json.dumps(metrics, indent=2, sort_keys=True, default=str))
    return 0


def _cmd_config(args: argparse.Namespace) -> int:
    cfg = _config(args)
    tree = config_dict(cfg)
    if args.json:
        print(json.dumps(tree, indent=1, sort_keys=True))
        return 0
    for section, fields in tree.items():
        for name, value in fields.items():
            print(f"{section}.{name} = {value}")
    print(f"hash (without policy name and seed): {config_hash(cfg)}")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    """Check --out before the render and --pose against the built world: an unknown image extension, a
    directory, an unwritable place or a camera outside the map or inside a wall would otherwise be a
    traceback or a silently wrong picture."""
    import io
    import os
    import warnings

    import numpy as np
    from PIL import Image

    from l3mvn.core.types import Pose, wrap_angle
    from l3mvn.core.writing import write_file
    from l3mvn.run.viz import colorize_depth, colorize_semantic, side_by_side
    from l3mvn.world.scenes.semexp import pick_floor
    from l3mvn.world.sim.render import Renderer
    from l3mvn.world.sim.simulator import random_walkable_pose
    from l3mvn.world.sim.world import build_world

    def writes_rgb(fmt: str) -> bool:
        """Whether PIL can encode our RGB panel as ``fmt`` (XBM, MSP, ... cannot; tried on one pixel)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # deprecation notices of formats the user did not pick
            try:
                Image.new("RGB", (1, 1)).save(io.BytesIO(), format=fmt)
            except (OSError, ValueError, KeyError, TypeError):
                return False
        return True

    def checked_out(text: str) -> tuple[Path, str]:
        out = Path(text)
        if "\0" in text:
            raise L3MVNError(f"--out {text!r} contains a NUL character")
        if out.is_dir():
            raise L3MVNError(f"--out {text} is a directory; give an image file such as {out / 'frame.png'}")
        Image.init()
        extensions = Image.registered_extensions()
        fmt = extensions.get(out.suffix.lower())
        if fmt is None or not writes_rgb(fmt):
            problem = f"unknown image extension {out.suffix!r}" if out.suffix else "no image extension"
            if fmt is not None:
                problem = f"{fmt} cannot hold an RGB image"
            valid = sorted(ext for ext, f in extensions.items() if writes_rgb(f))
            raise L3MVNError(f"--out {text}: {problem}; valid: {', '.join(valid)}")
        out.parent.mkdir(parents=True, exist_ok=True)
        if not os.access(out.parent, os.W_OK):
            raise L3MVNError(f"--out {text}: {out.parent} is not writable")
        return out, fmt

    def checked_pose(text: str, scene, world) -> Pose:
        try:
            x, y, h = (float(v) for v in text.split(","))
        except ValueError:
            raise L3MVNError(f"--pose must be X,Y,HEADING_DEG (metres, degrees), got {text!r}") from None
        if not all(math.isfinite(v) for v in (x, y, h)):
            raise L3MVNError(f"--pose needs finite numbers, got {text!r}")
        if not scene.contains(x, y):
            raise L3MVNError(
                f"--pose {x:g},{y:g} lies outside the map of {scene.key}, which spans {scene.extent_text()}"
            )
        r, c = scene.cell_of(x, y)
        if world.walls[r, c] or world.furniture[r, c] or scene.object_any[r, c]:
            raise L3MVNError(
                f"--pose {x:g},{y:g} is off the floor of {scene.key}: cell ({r}, {c}) is a wall, "
                "furniture or an object; omit --pose for a random navigable pose"
            )
        return Pose(x, y, wrap_angle(math.radians(h)))

    cfg = _config(args).sim
    try:
        out, fmt = checked_out(args.out)
    except OSError as exc:  # a parent that is a file, a name too long, no permission
        raise L3MVNError(f"--out {args.out}: cannot write there ({exc.strerror or exc})") from None
    source, scenes = _scenes(args, Config(sim=cfg))
    name = args.scene or sorted(scenes)[0]
    scene = pick_floor(scenes, name, args.floor, where=str(source))
    world = build_world(scene, cfg)
    if args.pose is not None:  # an empty --pose is a mistake, not a request for a random pose
        pose = checked_pose(args.pose, scene, world)
    else:
        pose = random_walkable_pose(scene, np.random.default_rng(args.seed))
    frame = Renderer(world, cfg).render(pose, 0.0)
    panel = side_by_side(
        frame.rgb, colorize_depth(frame.depth, cfg.max_depth_m), colorize_semantic(frame.semantic, scene.categories)
    )
    encoded = io.BytesIO()
    try:
        Image.fromarray(panel).save(encoded, format=fmt)
    except (OSError, ValueError) as exc:
        raise L3MVNError(f"--out {args.out}: cannot encode the image as {fmt} ({exc}); use .png") from None
    write_file(out, encoded.getvalue(), "--out")
    print(
        f"wrote {args.out}: {scene.key} at x={pose.x:.2f} y={pose.y:.2f} heading={math.degrees(pose.heading):.0f} deg"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
