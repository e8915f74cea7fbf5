"""Per-batch records of a `lerobot-ocr eval` run, so that an interrupted run resumes where it stopped.

lerobot-eval runs its episodes batch after batch (`--eval.batch_size` envs each, env seeds
`--seed` + episode index) and keeps its results in memory until the last one (only videos are written
as it goes). `run_eval` records each finished batch in `<output_dir>/batches/batch_<k>.npz`: the
rollout's tensors (`reward`, `success`, `done`: (B, T); `action`: (B, T, A)), ocr_joint's `ocr_stats()`
for it, the actions per decision of a chunking policy, its seeds and seconds, and the RNG states (torch
CPU and CUDA, NumPy, Python) right after it. A run with `--ocr.resume=true`, the same arguments and
checkpoint (and the same code: like `lerobot-train --resume`, the code is not checked) replays the
batches it finds instead of simulating them, then sets the RNG states the last one left: the episodes
after it are the ones the uninterrupted run would have had (bit for bit on CPU, where torch's kernels
are deterministic). Batches whose videos are missing (cut while writing them) run again, rendering.
Writing a record takes milliseconds; one process, so none of the ≈ 80 s that an extra eval process
costs on Square (`benchmarks/EXPERIMENTS.md`, "Resumable eval cells in chunks").

`replayable_batches` reads the records back for a replay of the episodes (`benchmarks/*_failures.py`).

Our own: lerobot-eval has no resume, and `lerobot-train --resume` covers training only.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import random
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

RECORDS_DIR = "batches"
# flags that do not change a batch's episodes: how many batches run, where, which are rendered, resuming,
# and our budgets (read after the run)
_KEY_IGNORES = (
    "eval.n_episodes",
    "output_dir",
    "ocr.videos",
    "ocr.resume",
    "ocr.step_budget",
    "ocr.decision_budget",
    "ocr.recovery_call_steps",
)
_STATS_ARRAYS = ("score", "in_recovery", "decisions")
# Bump when a change alters the episodes of the same command (env wrappers, the policy's sampling, the
# record format): records of older code then start over instead of mixing. 2: finished envs frozen.
RECORD_VERSION = 2


def joined_args(args: list[str]) -> list[str]:
    """CLI strings with every `--flag value` pair written `--flag=value` (both are valid for draccus), so
    that one form can be read and hashed."""
    out, i = [], 0
    while i < len(args):
        a = args[i]
        if a.startswith("--") and "=" not in a and i + 1 < len(args) and not args[i + 1].startswith("--"):
            out.append(f"{a}={args[i + 1]}")
            i += 2
        else:
            out.append(a)
            i += 1
    return out


def hash_files(digest, root: Path, pattern: str = "*") -> None:
    """Feed a file's, or a folder's files' (those matching `pattern`, recursively, sorted) names relative
    to `root` and bytes into the hashlib object `digest`."""
    files = [root] if root.is_file() else sorted(p for p in root.rglob(pattern) if p.is_file())
    for f in files:
        digest.update(str(f.relative_to(root) if f != root else f.name).encode())
        with open(f, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)


def run_key(args: list[str]) -> str:
    """The identity of a run's batches: its arguments (those that change episodes, in order), its
    checkpoint and config file, `RECORD_VERSION` and LeRobot's version.

    `args`: the eval's CLI strings (`lerobot-ocr eval`'s, ours included; `--flag value` pairs count as
    `--flag=value`). The `--policy.path` folder (the last one given) is hashed file by file (names and
    bytes: a retrained checkpoint under the same path is another run), a hub id counts as its string;
    a `--config_path` file is hashed too. Our own code is not (`RECORD_VERSION` stands for it).
    """
    from importlib.metadata import version

    args = joined_args(args)
    kept = [a for a in args if not any(a.startswith(f"--{flag}=") for flag in _KEY_IGNORES)]
    digest = hashlib.sha256(json.dumps([RECORD_VERSION, version("lerobot"), kept]).encode())
    for flag in ("policy.path", "config_path"):
        values = [a.split("=", 1)[1] for a in args if a.startswith(f"--{flag}=")]
        if values and Path(values[-1]).exists():
            hash_files(digest, Path(values[-1]))
    return digest.hexdigest()


def video_is_complete(path: Path) -> bool:
    """Whether `path` is a video that opens and holds frames (one cut while being written has no index)."""
    import av

    try:
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            return bool(stream.frames) or any(True for _ in container.decode(stream))
    except (OSError, IndexError, av.error.FFmpegError):
        return False


def rng_states() -> dict[str, np.ndarray]:
    """This process's RNG states as arrays (torch CPU, CUDA if initialised, NumPy's and Python's global)."""
    import torch

    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    version, state, gauss_next = random.getstate()
    out = {
        "rng.torch": torch.get_rng_state().numpy(),
        "rng.numpy_keys": np.asarray(keys, dtype=np.uint32),
        "rng.numpy": np.asarray(json.dumps([kind, int(pos), int(has_gauss), float(gauss)])),
        "rng.python_state": np.asarray(state, dtype=np.int64),
        "rng.python": np.asarray(json.dumps([version, gauss_next])),
    }
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        out["rng.cuda"] = np.stack([s.numpy() for s in torch.cuda.get_rng_state_all()])
    return out


def set_rng_states(arrays) -> None:
    """Undo `rng_states`: set this process's RNGs to the recorded states."""
    import torch

    torch.set_rng_state(torch.from_numpy(np.array(arrays["rng.torch"])))
    kind, pos, has_gauss, gauss = json.loads(str(arrays["rng.numpy"]))
    np.random.set_state((kind, np.array(arrays["rng.numpy_keys"]), pos, has_gauss, gauss))
    version, gauss_next = json.loads(str(arrays["rng.python"]))
    random.setstate((version, tuple(int(x) for x in arrays["rng.python_state"]), gauss_next))
    if "rng.cuda" in arrays and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([torch.from_numpy(s) for s in np.array(arrays["rng.cuda"])])


def _meta(path: Path) -> dict | None:
    """A record's metadata; None if the file cannot be read (cut short by a crash of the machine)."""
    try:
        with np.load(path) as z:
            return json.loads(str(z["meta"]))
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # missing, truncated, not ours
        return None


def recorded_metas(output_dir: str | Path) -> list[dict]:
    """The metadata of the readable batches recorded in `<output_dir>/batches/` (key, batch, rows, seeds,
    seconds, ...), in file order."""
    metas = (_meta(f) for f in sorted((Path(output_dir) / RECORDS_DIR).glob("batch_*.npz")))
    return [m for m in metas if m is not None]


def recorded_keys(output_dir: str | Path) -> set[str]:
    """The `run_key`s of the readable batches recorded in `<output_dir>/batches/` (empty: none)."""
    return {m["key"] for m in recorded_metas(output_dir)}


def finished_episodes(output_dir: str | Path) -> int | None:
    """How many episodes the finished eval in `output_dir` counts (its `eval_info.json`; lerobot-eval runs
    whole batches and drops the rows past `--eval.n_episodes`); None when it has not finished."""
    info = Path(output_dir) / "eval_info.json"
    if not info.exists():
        return None
    return sum(len(t["metrics"]["successes"]) for t in json.loads(info.read_text())["per_task"])


def replayable_batches(
    output_dir: str | Path, names: tuple[str, ...]
) -> Iterator[tuple[list[int], dict[str, np.ndarray]]]:
    """Yield (seeds, arrays) per batch recorded in `<output_dir>/batches/`, in file order, to re-simulate
    its episodes: the env seeds of its rows and its arrays `names` as recorded ("rollout.<name>": (B, T,
    ...), "stats.<name>": (T, B)). Rows lerobot-eval ran past the cell's episodes (its last batch runs
    whole; `eval_info.json` counts them) are left out of the seeds, so index the arrays by the seeds.

    Raises:
        ValueError: a batch recorded without seeds (an unseeded eval cannot be replayed).
    """
    left = finished_episodes(output_dir)
    for f in sorted((Path(output_dir) / RECORDS_DIR).glob("batch_*.npz")):
        with np.load(f) as z:
            seeds = json.loads(str(z["meta"]))["seeds"]
            arrays = {name: z[name] for name in names}
        if seeds is None:
            raise ValueError(
                f"{f} was recorded without env seeds: only a seeded eval (--seed) can be replayed."
            )
        if left is not None:
            seeds, left = seeds[: max(left, 0)], left - len(seeds)
        if seeds:
            yield seeds, arrays


class BatchRecords:
    """The finished batches of one eval run in `<output_dir>/batches/`, written atomically.

    Args:
        output_dir: the eval's `--output_dir`.
        key: `run_key(...)` of the run.
        resume: keep and replay the records found (`--ocr.resume=true`); otherwise remove them.

    Raises:
        ValueError: `resume` and the folder holds batches of another run (other arguments or checkpoint);
            they are left in place.
    """

    def __init__(self, output_dir: str | Path, key: str, resume: bool):
        self.dir, self.key = Path(output_dir) / RECORDS_DIR, key
        for f in self.dir.glob(".batch_*.tmp"):  # left by a cut while saving
            f.unlink()
        if not resume:  # this run's records and videos replace any earlier run's
            for f in [*self.dir.glob("batch_*.npz"), *Path(output_dir).glob("videos/*/eval_episode_*.mp4")]:
                f.unlink()
        elif recorded_keys(output_dir) - {key}:
            raise ValueError(
                f"{self.dir} holds eval batches of another run (other arguments or checkpoint). "
                "Resume only with the arguments and checkpoint of the run that wrote them, or pass "
                "a fresh --output_dir (or leave out --ocr.resume=true to start this one over)."
            )
        # batches 0..n-1, readable and without a gap: only a prefix can be replayed in seed order
        self.metas: list[dict] = []
        while (meta := _meta(self.dir / self._name(len(self.metas)))) is not None:
            self.metas.append(meta)
        self.n_found = len(self.metas)
        for f in self.dir.glob("batch_*.npz"):  # an unreadable record and those after it run again
            if int(f.stem.split("_")[1]) >= self.n_found:
                f.unlink()
        self.live_until = 0  # batches below it run again although recorded (`render_again`)

    def check_seeds(self, start_seed: int | None, rows: int) -> None:
        """Before anything runs: every recorded batch k ran the env seeds this run gives it,
        `start_seed + k·rows` onward (lerobot-eval's order).

        Raises:
            ValueError: unseeded episodes (`--seed` None cannot be replayed), or other seeds (another
                batch size: lerobot-eval caps it at `--eval.n_episodes`, its default depends on the cores).
        """
        if not self.n_found:
            return
        if start_seed is None:
            raise ValueError("--ocr.resume=true needs seeded episodes: pass the interrupted run's --seed.")
        for k in range(self.n_found):
            self._require_seeds(k, range(start_seed + k * rows, start_seed + (k + 1) * rows))

    def _require_seeds(self, k: int, seeds) -> None:
        """Raise ValueError unless recorded batch `k` ran the env seeds `seeds` (None: unseeded)."""
        seeds = None if seeds is None else [int(x) for x in seeds]
        if self.metas[k]["seeds"] != seeds:
            raise ValueError(
                f"Batch {k} in {self.dir} ran env seeds {self.metas[k]['seeds']}, this run gives it {seeds}: "
                "resume with the interrupted run's --eval.batch_size and --seed (and --eval.n_episodes of "
                "at least the batch size), or start over without --ocr.resume=true."
            )

    def render_again(self, videos_dir: Path, rendered: int) -> bool:
        """Whether the recorded batches holding the first `rendered` episodes (at most the rows of the run's
        batches: LeRobot renders every row of a batch) must run again to render their videos
        (`<videos_dir>/*/eval_episode_<i>.mp4`, lerobot-eval's names): True when one is missing or
        unreadable (cut while being written), or when episodes past the recorded ones are to be rendered
        too (a live batch would number its videos from 0 again).
        Sets `live_until` to the batches that then run live."""
        if not self.n_found or rendered <= 0:
            return False
        rows = self.metas[0]["rows"]
        files = [sorted(Path(videos_dir).glob(f"*/eval_episode_{i}.mp4")) for i in range(rendered)]
        done = rendered <= self.n_found * rows and all(f and video_is_complete(f[0]) for f in files)
        self.live_until = 0 if done else min(self.n_found, math.ceil(rendered / rows))
        return not done

    def replays(self, k: int) -> bool:
        """Whether batch `k` is replayed from its record (else it runs)."""
        return self.live_until <= k < self.n_found

    @staticmethod
    def _name(k: int) -> str:
        return f"batch_{k:05d}.npz"

    def save(
        self,
        k: int,
        rollout: dict,
        stats: dict | None,
        chunk_steps: int | None,
        seeds: list[int] | None,
        seconds: float,
    ) -> None:
        """Record batch `k`: `rollout` (lerobot's rollout dict, tensors), `stats` (ocr_joint's
        `ocr_stats()` for it, or None), its env seeds, its wall time and the current RNG states.
        Atomic and durable: a temp file, synced, then a rename."""
        import torch

        # the tensors lerobot-eval reads (observations, only returned for online training, are not kept)
        arrays = {f"rollout.{n}": t.detach().cpu().numpy() for n, t in rollout.items() if torch.is_tensor(t)}
        scalars = None
        if stats is not None:
            scalars = {k_: v for k_, v in stats.items() if k_ not in _STATS_ARRAYS}
            for name in _STATS_ARRAYS:
                if stats.get(name) is not None:
                    arrays[f"stats.{name}"] = np.asarray(stats[name])
        seeds = None if seeds is None else [int(x) for x in seeds]
        meta = {"key": self.key, "batch": k, "rows": int(rollout["done"].shape[0]), "seeds": seeds,
                "seconds": seconds, "chunk_steps": chunk_steps, "stats": scalars}  # fmt: skip
        self.dir.mkdir(parents=True, exist_ok=True)
        tmp = self.dir / f".{self._name(k)}.tmp"
        with open(tmp, "wb") as f:
            np.savez(f, meta=np.asarray(json.dumps(meta)), **arrays, **rng_states())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.dir / self._name(k))
        fd = os.open(self.dir, os.O_RDONLY)  # the rename itself survives a crash of the machine
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    def load(self, k: int, seeds: list[int] | None) -> tuple[dict, dict | None, int | None]:
        """Replay batch `k`, which this run gives the env seeds `seeds`: set the RNG states recorded
        after it; return (rollout tensors, ocr stats or None, actions per decision).

        Raises:
            ValueError: the recorded batch ran other seeds (another batch size: lerobot-eval caps it at
                `--eval.n_episodes`, and its default depends on the machine's cores).
        """
        import torch

        self._require_seeds(k, seeds)
        with np.load(self.dir / self._name(k)) as z:
            meta = json.loads(str(z["meta"]))
            names = [n for n in z.files if n.startswith("rollout.")]
            rollout = {n.split(".", 1)[1]: torch.from_numpy(z[n]) for n in names}
            stats = meta["stats"]
            if stats is not None:
                stats = {**stats, **{n: z.get(f"stats.{n}") for n in _STATS_ARRAYS}}
            set_rng_states({n: z[n] for n in z.files if n.startswith("rng.")})
        return rollout, stats, meta["chunk_steps"]
