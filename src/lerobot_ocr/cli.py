"""The `lerobot-ocr` command line."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

TORCHCODEC_NOTE = (
    "torchcodec cannot be loaded ({reason}); LeRobot decodes videos with pyav instead. Without FFmpeg 4-8 "
    "on the system this is expected: install it (e.g. `apt install ffmpeg`) to use torchcodec."
)


class TorchcodecNote(logging.Filter):
    """LeRobot logs torchcodec's whole loading traceback (~100 lines, per process) when it cannot load,
    although it then falls back to pyav and works: say it in one line, keeping the error's first line."""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if "'torchcodec' is installed but cannot be loaded" in message:
            if "libavutil" in message and "cannot open shared object file" in message:
                reason = "FFmpeg's shared libraries (libavutil) are not on this system"
            else:  # another cause (e.g. a torch / torchcodec mismatch): keep its first line
                reason = message.strip().splitlines()[0].split(" Likely causes")[0].strip().rstrip(".:")
            record.msg, record.args = TORCHCODEC_NOTE.format(reason=reason), ()
        return True


def quiet_known_warnings() -> None:
    """Shorten LeRobot's torchcodec traceback to one line; every other message stays as it is."""
    logger = logging.getLogger("lerobot.utils.import_utils")
    if not any(isinstance(f, TorchcodecNote) for f in logger.filters):
        logger.addFilter(TorchcodecNote())


def _demo(args: argparse.Namespace) -> int:
    if args.what == "manifold" and (args.checkpoint or args.from_scratch or args.task != "pusht"):
        raise SystemExit("lerobot-ocr demo manifold takes none of --task, --checkpoint, --from-scratch.")
    if args.what == "pusht" and args.from_scratch:
        if args.checkpoint or args.task != "pusht":
            raise SystemExit("--from-scratch trains Push-T's tiny chain; it takes no --checkpoint or --task.")
        from lerobot_ocr.demo import demo_from_scratch

        demo_from_scratch(args.output_dir or "outputs/demo", restart=args.restart)
        return 0
    if args.what == "pusht":
        from lerobot_ocr.demo import DEMO_EPISODES, demo

        try:
            demo(
                args.task,
                args.checkpoint,
                args.output_dir,
                episodes=args.episodes or DEMO_EPISODES,
                restart=args.restart,
            )
        except (FileNotFoundError, FileExistsError, ValueError) as e:  # what to pass or restore instead
            raise SystemExit(str(e)) from None
        return 0
    from lerobot_ocr.manifold_demo import run_manifold_demo

    summary = run_manifold_demo(
        args.output_dir or "outputs/demo_manifold",
        episodes=args.episodes or 50,
        n_components=args.n_components,
        seed=args.seed,
    )
    print(json.dumps(summary, indent=2))
    print(f"\nDensity field with recovery arrows: {summary['picture']}")
    return 0


def env_options(task: str, args: list[str]) -> dict:
    """`--env.<field>=<value>` flags (as lerobot-eval takes them) -> {field: value} for the task's env config.

    Raises:
        SystemExit: an argument that is not `--env.<field>=<value>`, or a field the env config lacks.
    """
    import draccus

    from lerobot_ocr.envs.configs import PushtOcrEnvConfig, SquareOcrEnvConfig

    cls = {"pusht": PushtOcrEnvConfig, "square": SquareOcrEnvConfig}[task]
    bad = [a for a in args if not (a.startswith("--env.") and "=" in a)]
    if bad:
        raise SystemExit(
            f"lerobot-ocr generate: unrecognized arguments {bad}; env settings are --env.<field>=<value>."
        )
    pairs = [a[len("--env.") :].split("=", 1) for a in args]
    try:
        cfg = draccus.parse(cls, args=[f"--{k}={v}" for k, v in pairs])
    except BaseException as e:  # draccus exits on a bad field; say which config it belongs to
        fields = sorted(f for f in cls.__dataclass_fields__ if not f.startswith("_"))
        raise SystemExit(
            f"lerobot-ocr generate: bad env setting in {args}; {cls.__name__} fields: {fields}"
        ) from e
    return {k: getattr(cfg, k) for k, _ in pairs}


def _generate(args: argparse.Namespace, extra: list[str]) -> int:
    options = env_options(args.task, extra)
    region = options.pop("region", args.region)
    common = dict(
        episodes=args.episodes,
        region=region,
        repo_id=args.repo_id or f"local/{args.task}_ocr",
        seed=args.seed,
        use_videos=not args.no_videos,
        push_to_hub=args.push_to_hub,
        private=args.private,
        keep_work=args.keep_work,
        env_options=options,
        overwrite=args.overwrite,
    )
    if args.task == "pusht":
        from lerobot_ocr.datagen.pusht import generate_pusht

        ds = generate_pusht(args.root, **common)
    else:
        from lerobot_ocr.datagen.square import generate_square

        ds = generate_square(args.root, images=not args.no_images, **common)
    print(
        f"Wrote {ds.meta.total_episodes} episodes / {ds.meta.total_frames} frames to {args.root} (repo_id "
        f"{ds.repo_id})."
    )
    return 0


def _convert(args: argparse.Namespace) -> int:
    from lerobot_ocr.convert import convert_dataset

    ds = convert_dataset(
        args.repo_id,
        args.output_root,
        args.object,
        args.pose_from,
        root=args.root,
        output_repo_id=args.output_repo_id,
        pose_rotation=args.pose_rotation,
        source_keypoints=args.source_keypoints,
        push_to_hub=args.push_to_hub,
        private=args.private,
        overwrite=args.overwrite,
    )
    print(
        f"Wrote {ds.meta.total_episodes} episodes / {ds.meta.total_frames} frames with "
        f"observation.object_pose and observation.object_keypoints to {args.output_root} (repo_id "
        f"{ds.repo_id})."
    )
    return 0


def _eval(args: argparse.Namespace) -> int:
    from lerobot_ocr.eval_report import format_start_split, format_table, run_eval

    result = run_eval(args.lerobot_eval_args)
    print(json.dumps(result))
    print("\n" + format_table({"eval": result}))
    split = format_start_split({"eval": result})
    if split:
        print(split)
    return 0


def _collect(argv: list[str]) -> int:
    from lerobot_ocr.continual.collect import main as collect_main

    ds = collect_main(argv)
    print(
        f"Wrote {ds.meta.total_episodes} episodes / {ds.meta.total_frames} frames to {ds.root} "
        f"(repo_id {ds.repo_id})."
    )
    return 0


def _merge(args: argparse.Namespace) -> int:
    from lerobot_ocr.continual.merge import merge

    sources = [(root, f"local/{Path(root).name}") for root in [args.base, *args.add]]
    ds = merge(
        sources,
        args.output_root,
        args.output_repo_id or f"local/{Path(args.output_root).name}",
        push_to_hub=args.push_to_hub,
        private=args.private,
        overwrite=args.overwrite,
    )
    print(
        f"Wrote {ds.meta.total_episodes} episodes / {ds.meta.total_frames} frames to {args.output_root} "
        f"(repo_id {ds.repo_id}); provenance in meta/ocr_continual.json."
    )
    return 0


def _rebase(args: argparse.Namespace) -> int:
    from lerobot_ocr.continual.rebase import rebase

    out = rebase(args.policy_path, args.base_path, args.output_dir, overwrite=args.overwrite)
    print(f"Wrote {out}: the ocr_joint checkpoint with {args.base_path} as its base (--policy.path={out}).")
    return 0


def _upgrade(args: argparse.Namespace) -> int:
    from lerobot_ocr.retired import upgrade_checkpoint

    changed = upgrade_checkpoint(args.path)
    for file, removed in changed.items():
        print(f"{file}: removed {', '.join(f'{k}={v}' for k, v in removed.items())}")
    print(f"{len(changed)} file(s) changed." if changed else "Nothing to remove: the checkpoint is current.")
    return 0


def _push(args: argparse.Namespace) -> int:
    from lerobot_ocr.hub import push_folder

    push_folder(args.root, args.repo_id, private=args.private)
    print(f"Pushed {args.root} to the hub as {args.repo_id}.")
    return 0


def _add_hub_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--push-to-hub",
        action="store_true",
        help="Upload the dataset to the hub under its repo id when done.",
    )
    parser.add_argument("--private", action="store_true", help="Make the hub repo private.")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lerobot-ocr", description="Object-Centric Recovery for LeRobot policies."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser(
        "demo",
        help="Run the published checkpoint's base and its ocr_joint on the same OOD starts (nothing trained; "
        "Push-T about 3-5 min on 2 cores, --task square longer): table, success chart, density field, and "
        "the videos of a start where the base fails and ocr_joint recovers. --from-scratch: the tiny "
        "train-everything chain instead. `demo manifold`: the keypoint manifold on synthetic data.",
    )
    demo.add_argument(
        "what",
        nargs="?",
        choices=["pusht", "manifold"],
        default="pusht",
        help="pusht (default): the policy demo (--task picks the task); manifold: the manifold only.",
    )
    demo.add_argument(
        "--task",
        choices=["pusht", "square"],
        default="pusht",
        help="the task whose published checkpoint runs (square: about 10 min on 2 cores).",
    )
    demo.add_argument(
        "--checkpoint",
        default=None,
        help="an ocr_joint pretrained_model folder (its base in base/) or a hub id; default the clone's "
        "published checkpoints/<task>_cpu.",
    )
    demo.add_argument(
        "--from-scratch",
        action="store_true",
        help="train the tiny Push-T chain here instead (about 15 min; its networks are too small to "
        "succeed).",
    )
    demo.add_argument(
        "--output-dir",
        default=None,
        help="Work dir (default outputs/demo_<task>, outputs/demo with "
        "--from-scratch, outputs/demo_manifold).",
    )
    demo.add_argument("--restart", action="store_true", help="start over instead of resuming.")
    demo.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="OOD starts per policy (default 30); manifold: synthetic demonstrations (default 50).",
    )
    demo.add_argument(
        "--n-components", type=int, default=4, help="manifold: Gaussian components per keypoint."
    )
    demo.add_argument(
        "--seed", type=int, default=0, help="manifold: the seed of the synthetic data and the fit."
    )
    demo.set_defaults(func=_demo)

    gen = sub.add_parser(
        "generate",
        help="Generate scripted-expert demonstrations as a LeRobotDataset; other env settings as "
        "--env.<field>=<value>.",
    )
    gen.add_argument(
        "task", choices=["pusht", "square"], help="Which task (square needs the [square] extra)."
    )
    gen.add_argument(
        "--region", choices=["id", "ood", "all"], default="id", help="Start region of the demos."
    )
    gen.add_argument(
        "--episodes",
        type=int,
        default=100,
        help="Successful episodes to keep (paper: 100 Push-T, 200 Square).",
    )
    gen.add_argument("--root", required=True, help="Output folder of the dataset (resumes if interrupted).")
    gen.add_argument(
        "--repo-id",
        default=None,
        help="Dataset repo id (for the hub and metadata; default local/<task>_ocr).",
    )
    gen.add_argument("--seed", type=int, default=0, help="Attempt j uses env seed SEED + j.")
    gen.add_argument(
        "--no-videos", action="store_true", help="Store images in parquet instead of mp4 videos."
    )
    gen.add_argument(
        "--no-images", action="store_true", help="square: record low-dim observations only (no cameras)."
    )
    _add_hub_flags(gen)
    gen.add_argument("--keep-work", action="store_true", help="Keep the per-episode cache <root>.work/.")
    gen.add_argument(
        "--overwrite",
        action="store_true",
        help="Replace a finished dataset at --root, or an unfinished run's cache made with other settings "
        "(else an unfinished run resumes).",
    )
    gen.set_defaults(func=_generate)

    conv = sub.add_parser(
        "convert",
        help="Add object pose + keypoints (observation.object_pose / observation.object_keypoints) to a "
        "LeRobotDataset.",
    )
    conv.add_argument("--repo-id", required=True, help="Source dataset repo id.")
    conv.add_argument(
        "--root", default=None, help="Local folder of the source dataset (else the HF cache / hub)."
    )
    conv.add_argument(
        "--object",
        required=True,
        help="Object keypoint spec: pusht_t, pusht_corners, axes:0.05, or a .npy/.json file.",
    )
    conv.add_argument(
        "--pose-from",
        required=True,
        help="Pose source: feature:<name> (a pose feature), keypoints:<name> (flattened world keypoints, "
        "rigidly fitted), estimator:<module>:<function> (called on every decoded frame), or "
        "state:<prefix> / state:<name>,<name> (entries of observation.state, e.g. state:object_).",
    )
    conv.add_argument("--output-root", required=True, help="Folder of the converted dataset.")
    conv.add_argument(
        "--output-repo-id", default=None, help="Repo id of the converted dataset (default <repo-id>_ocr)."
    )
    conv.add_argument(
        "--pose-rotation",
        default=None,
        help="Pose representation: angle (2D) | quat_wxyz | quat_xyzw | axis_angle | rot6d.",
    )
    conv.add_argument(
        "--source-keypoints", default=None, help="Layout of a keypoints:<name> source (default: --object)."
    )
    _add_hub_flags(conv)
    conv.add_argument("--overwrite", action="store_true", help="Replace a finished dataset at --output-root.")
    conv.set_defaults(func=_convert)

    ev = sub.add_parser(
        "eval",
        help="Run lerobot-eval (same arguments) and add a summary table + ocr_stats.json (recovery "
        "fraction).",
    )
    ev.add_argument("lerobot_eval_args", nargs="*", help="Arguments for lerobot-eval, incl. --output_dir=…")
    ev.set_defaults(func=_eval)

    sub.add_parser(
        "collect",
        help="Run a policy (ocr_joint for OCR collection) in a sim env and keep its episodes as a "
        "LeRobotDataset with the features of --like=<the base's dataset> (lerobot-eval's flags plus "
        "--like, --root, --repo_id, --episodes, --keep=episode|recovery|all, --push_to_hub=true, "
        "--overwrite=true).",
        add_help=False,
    )

    mrg = sub.add_parser(
        "merge",
        help="Merge the base's dataset with collected ones (LeRobot's merge_datasets), with provenance.",
    )
    mrg.add_argument("--base", required=True, help="Folder of the base's training dataset.")
    mrg.add_argument(
        "--add", action="append", required=True, help="Folder of a collected dataset (repeatable)."
    )
    mrg.add_argument("--output-root", required=True, help="Folder of the merged dataset.")
    mrg.add_argument(
        "--output-repo-id", default=None, help="Repo id of the merged dataset (default local/<folder>)."
    )
    _add_hub_flags(mrg)
    mrg.add_argument("--overwrite", action="store_true", help="Replace a finished dataset at --output-root.")
    mrg.set_defaults(func=_merge)

    reb = sub.add_parser(
        "rebase", help="Copy an ocr_joint checkpoint with another (e.g. retrained) base policy."
    )
    reb.add_argument(
        "--policy-path", required=True, help="The ocr_joint checkpoint (pretrained_model folder)."
    )
    reb.add_argument("--base-path", required=True, help="The new base policy (pretrained_model folder).")
    reb.add_argument("--output-dir", required=True, help="Folder of the new ocr_joint checkpoint.")
    reb.add_argument("--overwrite", action="store_true", help="Replace a checkpoint at --output-dir.")
    reb.set_defaults(func=_rebase)

    upg = sub.add_parser(
        "upgrade",
        help="Remove retired ocr_joint options from a checkpoint's config.json / train_config.json, so it "
        "loads again (options measured and not adopted; see benchmarks/EXPERIMENTS.md).",
    )
    upg.add_argument(
        "path", help="A pretrained_model folder, or a training output folder (all its checkpoints)."
    )
    upg.set_defaults(func=_upgrade)

    push = sub.add_parser(
        "push", help="Push a finished local LeRobotDataset to the hub (e.g. after a failed push)."
    )
    push.add_argument("--root", required=True, help="Folder of the dataset.")
    push.add_argument("--repo-id", required=True, help="Hub repo id, e.g. you/pusht_ocr_collected.")
    push.add_argument("--private", action="store_true", help="Make the hub repo private.")
    push.set_defaults(func=_push)
    return parser


def main(argv: list[str] | None = None) -> int:
    quiet_known_warnings()
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["eval"] and not {"-h", "--help"} & set(argv[1:]):
        # lerobot-eval's own `--key=value` flags pass through untouched (argparse would claim them).
        return _eval(argparse.Namespace(lerobot_eval_args=argv[1:]))
    if argv[:1] == ["collect"]:  # LeRobot-style flags, parsed by LeRobot's own parser
        return _collect(argv[1:])
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if args.command == "generate":
        return args.func(args, extra)
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
