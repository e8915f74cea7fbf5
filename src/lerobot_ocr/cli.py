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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lerobot-ocr", description="Object-Centric Recovery for LeRobot policies.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="Fit the keypoint manifold on synthetic Push-T data and plot the recovery field.")
    demo.add_argument("--output-dir", default="outputs/demo", help="Where to write the PNG, manifold and summary.")
    demo.add_argument("--episodes", type=int, default=50, help="Synthetic demonstrations (60 frames each).")
    demo.add_argument("--n-components", type=int, default=4, help="Gaussian components per keypoint.")
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
