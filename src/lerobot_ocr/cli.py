"""The `lerobot-ocr` command line."""

from __future__ import annotations

import argparse
import json
import sys


def _demo(args: argparse.Namespace) -> int:
    from lerobot_ocr.demo import run_manifold_demo

    summary = run_manifold_demo(args.output_dir, episodes=args.episodes, n_components=args.n_components, seed=args.seed)
    print(json.dumps(summary, indent=2))
    print(f"\nDensity field with recovery arrows: {summary['picture']}")
    return 0


def _generate(args: argparse.Namespace) -> int:
    from lerobot_ocr.datagen.pusht import generate_pusht

    ds = generate_pusht(
        args.root, episodes=args.episodes, region=args.region, repo_id=args.repo_id, seed=args.seed,
        use_videos=not args.no_videos, push_to_hub=args.push_to_hub, private=args.private, keep_work=args.keep_work,
    )  # fmt: skip
    print(f"Wrote {ds.meta.total_episodes} episodes / {ds.meta.total_frames} frames to {args.root} (repo_id {args.repo_id}).")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lerobot-ocr", description="Object-Centric Recovery for LeRobot policies.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="Fit the keypoint manifold on synthetic Push-T data and plot the recovery field.")
    demo.add_argument("--output-dir", default="outputs/demo", help="Where to write the PNG, manifold and summary.")
    demo.add_argument("--episodes", type=int, default=50, help="Synthetic demonstrations (60 frames each).")
    demo.add_argument("--n-components", type=int, default=4, help="Gaussian components per keypoint.")
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_demo)

    gen = sub.add_parser("generate", help="Generate scripted-expert demonstrations as a LeRobotDataset.")
    gen.add_argument("task", choices=["pusht"], help="Which task.")
    gen.add_argument("--region", choices=["id", "ood", "all"], default="id", help="Start region of the demos.")
    gen.add_argument("--episodes", type=int, default=100, help="Successful episodes to keep.")
    gen.add_argument("--root", required=True, help="Output folder of the dataset (resumes if interrupted).")
    gen.add_argument("--repo-id", default="local/pusht_ocr", help="Dataset repo id (for the hub and metadata).")
    gen.add_argument("--seed", type=int, default=0, help="Attempt j uses env seed SEED + j.")
    gen.add_argument("--no-videos", action="store_true", help="Store images in parquet instead of mp4 videos.")
    gen.add_argument("--push-to-hub", action="store_true", help="Upload to the hub under --repo-id when done.")
    gen.add_argument("--private", action="store_true", help="Make the hub repo private.")
    gen.add_argument("--keep-work", action="store_true", help="Keep the per-episode cache <root>.work/.")
    gen.set_defaults(func=_generate)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
