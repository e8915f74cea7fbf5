"""The env-seed splits: which starts train, decide, collect and publish, defined once.

An episode's start (object pose, robot noise) is a function of its env seed; `lerobot-eval` gives
episode i of a run the seed `--seed + i`. Four disjoint ranges keep every number honest:

- `demos` (0..99999): the scripted demonstrations (`lerobot-ocr generate --seed 0`, attempt j seed j);
- `dev` (100000..199999): every probe, experiment and adoption decision;
- `collect` (300000..399999): the starts continual learning collects new demonstrations from;
- `test` (500000..599999): publication only. A published row is measured here, from a committed
  checkpoint, once; no experiment script may run on these seeds (`refuse_test`).

Pure data and checks: no simulator, no torch.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SeedRange:
    """Env seeds `start .. stop-1` of one split."""

    name: str
    start: int
    stop: int
    purpose: str

    def __contains__(self, seed: int) -> bool:
        return self.start <= seed < self.stop

    def covers(self, first: int, n: int) -> bool:
        """Whether the seeds `first .. first+n-1` all lie in this range."""
        return self.start <= first and first + max(n, 1) <= self.stop

    def __str__(self) -> str:
        return f"{self.name} (seeds {self.start}..{self.stop - 1})"


DEMOS = SeedRange("demos", 0, 100_000, "scripted demonstrations")
DEV = SeedRange("dev", 100_000, 200_000, "probes, experiments and adoption decisions")
COLLECT = SeedRange("collect", 300_000, 400_000, "continual-learning collection")
TEST = SeedRange("test", 500_000, 600_000, "published rows only, from committed checkpoints")
SPLITS = {s.name: s for s in (DEMOS, DEV, COLLECT, TEST)}
EVAL_SPLITS = ("dev", "test")  # the splits a benchmark cell may be measured on


class TestSplitRefused(ValueError):
    """An experiment was pointed at the test split's seeds."""

    __test__ = False  # not a pytest class


def split_of(first: int, n: int = 1) -> SeedRange | None:
    """The split holding all the seeds `first .. first+n-1`, or None when they lie outside every split.

    Raises:
        ValueError: the seeds straddle two splits (a run of `n` episodes from `first` crosses a boundary).
    """
    for s in SPLITS.values():
        if s.covers(first, n):
            return s
    last = first + max(n, 1) - 1
    touched = [s.name for s in SPLITS.values() if first < s.stop and last >= s.start]
    if len(touched) > 1 or (touched and not SPLITS[touched[0]].covers(first, n)):
        raise ValueError(
            f"Seeds {first}..{last} straddle the split boundary of {' and '.join(touched) or 'a split'}: "
            f"start a run inside one split ({', '.join(str(s) for s in SPLITS.values())})."
        )
    return None


LEROBOT_EVAL_EPISODES = 50  # lerobot-eval's default --eval.n_episodes


def command_seeds(cmd: list[str]) -> tuple[int, int] | None:
    """(first seed, episodes) of a `lerobot-eval` / `lerobot-ocr eval` command line: the last `--seed` and
    `--eval.n_episodes` win, as in draccus (`=` or a space; episodes default to lerobot-eval's 50). None
    when the command gives no `--seed`."""
    from lerobot_ocr.eval_resume import joined_args

    seed, n = None, LEROBOT_EVAL_EPISODES
    for a in joined_args(list(cmd)):  # `--seed 5` -> `--seed=5`, as draccus reads both
        if a.startswith("--seed="):
            seed = int(a.split("=", 1)[1])
        elif a.startswith("--eval.n_episodes="):
            n = int(a.split("=", 1)[1])
    return None if seed is None else (seed, n)


def refuse_test(first: int, n: int, who: str) -> None:
    """Raise when the seeds `first .. first+n-1` touch the test split: `who` (an experiment script) may
    run on any split but that one.

    Raises:
        TestSplitRefused: with the reason and what to run instead.
    """
    last = first + max(n, 1) - 1
    if first < TEST.stop and last >= TEST.start:
        raise TestSplitRefused(
            f"{who}: seeds {first}..{last} reach the test split {TEST}, which is kept for published rows: "
            "a rule chosen by looking at those starts would make every published number optimistic. "
            f"Probe and decide on the dev split {DEV} (the default). A row is published from a committed "
            "checkpoint with `benchmarks/<task>_ocr.py --from-checkpoint checkpoints/<task>_cpu`, which "
            "measures the test split."
        )


def refuse_test_command(
    cmd: list[str], who: str, seed: int | None = None, episodes: int | None = None
) -> None:
    """`refuse_test` on the seeds a command line runs (`command_seeds`): its own `--seed` and
    `--eval.n_episodes`, else `seed` and `episodes` (what the caller runs it with); a command with no seed
    from either passes.

    Raises:
        TestSplitRefused: the command's seeds reach the test split.
    """
    defaults = [f"--eval.n_episodes={episodes}"] if episodes is not None else []
    defaults += [] if seed is None else [f"--seed={seed}"]
    seeds = command_seeds([*defaults, *cmd])
    if seeds is not None:
        refuse_test(*seeds, who)
