"""Two eval runs on the same seeds, episode by episode: which solved what, and an exact McNemar test.

    .venv/bin/python benchmarks/paired.py outputs/probes/cpu4_joint_ood outputs/probes/cpu4_stall4

Each run is an `--output_dir` of `lerobot-ocr eval` (a probe or a chain cell) with its `episodes.json`,
or a probe's kept outcomes (`benchmarks/results/probe_episodes/<name>.json`, written by `probe.py`: they
outlive `outputs/`); both must have run the same seeds (`--seed`, same episode count), and kept outcomes
of two trainings (another digest of the weights) are refused. Per budget the runs report (strict:
within the step budget; reference budget: within the reference's decisions; whole episode), it prints
the success rates, the episodes solved only by the first and only by the second run, and the exact
two-sided McNemar p-value of those discordant counts (a binomial test with p = 1/2). The adopt rule
stays the interval one (`probe.py`); this says how sure a paired difference is.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "src")]

from lerobot_ocr.eval_report import budget_success  # noqa: E402
from lerobot_ocr.eval_resume import recorded_metas  # noqa: E402


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Exact two-sided McNemar p-value of discordant pair counts: 2 * P(X <= min) for X ~ Bin(n, 1/2),
    capped at 1 (1.0 with no discordant pair)."""
    n = only_a + only_b
    k = min(only_a, only_b)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2**n
    return min(1.0, 2 * tail)


def solved_flags(run: Path) -> tuple[list[int] | None, dict[str, list[bool]]]:
    """(seeds, {budget: per-episode solved}) of one run's `episodes.json`, or of a probe's kept outcomes
    (a `.json` file) (budgets "strict", "reference_budget" when recorded, and "whole_episode"); the seeds
    are its recorded batches' (None without records).

    Raises:
        ValueError: the run has no episodes.json (an eval without our records).
    """
    if run.is_file():
        record = json.loads(run.read_text())
        episodes, seeds = record["episodes"], record.get("seeds") or []
    else:
        path = run / "episodes.json"
        if not path.exists():
            raise ValueError(f"{path} is missing: pass an --output_dir of `lerobot-ocr eval`.")
        episodes = json.loads(path.read_text())
        seeds = [s for m in recorded_metas(run) for s in (m.get("seeds") or [])]
    steps = episodes["success_step"]
    flags = {k: v["solved"] for k, v in budget_success(episodes, len(steps)).items() if k != "decision_count"}
    flags["whole_episode"] = [s > 0 for s in steps]
    seeds = seeds[: len(steps)]
    return (seeds if len(seeds) == len(steps) else None), flags


def kept_weights_digest(run: Path) -> str | None:
    """The digest of the weights kept with a probe's outcomes (None for a run folder)."""
    return json.loads(run.read_text()).get("weights_sha256") if run.is_file() else None


def compare(a: Path, b: Path) -> dict[str, dict]:
    """Per budget both runs report: rates, discordant counts and the exact McNemar p-value.

    Raises:
        ValueError: the runs did not run the same episodes (seeds or count), or kept outcomes of two
            trainings.
    """
    digests = {kept_weights_digest(a), kept_weights_digest(b)} - {None}
    if len(digests) > 1:
        raise ValueError(
            f"{a} and {b} ran other weights (their digests differ): pair runs of one training; a chain "
            "rebuilt on another CPU model trains other weights."
        )
    seeds_a, fa = solved_flags(a)
    seeds_b, fb = solved_flags(b)
    counts = {len(v) for v in (*fa.values(), *fb.values())}
    if len(counts) > 1 or (seeds_a is not None and seeds_b is not None and seeds_a != seeds_b):
        raise ValueError(f"{a} and {b} ran other episodes (seeds or count): a paired test needs the same.")
    out = {}
    for budget in (k for k in fa if k in fb):
        x, y = fa[budget], fb[budget]
        only_a = sum(p and not q for p, q in zip(x, y))
        only_b = sum(q and not p for p, q in zip(x, y))
        out[budget] = {
            "n": len(x),
            "rate_a": sum(x) / len(x),
            "rate_b": sum(y) / len(y),
            "only_a": only_a,
            "only_b": only_b,
            "p_mcnemar": mcnemar_exact(only_a, only_b),
        }
    return out


def table(result: dict[str, dict]) -> str:
    """`compare`'s result as a Markdown table, one row per budget."""
    lines = [
        "| budget | episodes | a | b | solved only by a | solved only by b | exact McNemar p |",
        "|---|---|---|---|---|---|---|",
    ]
    for budget, r in result.items():
        lines.append(
            f"| {budget} | {r['n']} | {r['rate_a']:.3g} | {r['rate_b']:.3g} | {r['only_a']} | {r['only_b']} "
            f"| {r['p_mcnemar']:.2g} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", help="the first run's --output_dir or kept outcomes (the baseline)")
    parser.add_argument("b", help="the second run's --output_dir or kept outcomes (the change)")
    args = parser.parse_args()
    try:
        result = compare(Path(args.a), Path(args.b))
    except ValueError as e:
        parser.error(str(e))
    print(f"a = {args.a}\nb = {args.b}")
    print(table(result))


if __name__ == "__main__":
    main()
