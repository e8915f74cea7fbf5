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

Our own: lerobot-eval has no resume, and `lerobot-train --resume` covers training only.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import random
import zipfile
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


def run_key(args: list[str]) -> str:
    """The identity of a run's batches: its arguments (those that change episodes) and its checkpoint.

    `args`: the eval's CLI strings (`lerobot-ocr eval`'s, ours included). The `--policy.path` folder
    (the last one given) is hashed file by file (names and bytes: a retrained checkpoint under the same
    path is another run); a hub id counts as its string.
    """
    kept = [a for a in args if not any(a.startswith(f"--{flag}=") for flag in _KEY_IGNORES)]  # in order
    digest = hashlib.sha256(json.dumps(kept).encode())
    paths = [a.split("=", 1)[1] for a in args if a.startswith("--policy.path=")]
    folder = Path(paths[-1]) if paths else None
    if folder is not None and folder.is_dir():
        for f in sorted(p for p in folder.rglob("*") if p.is_file()):
            digest.update(str(f.relative_to(folder)).encode())
            with open(f, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    digest.update(block)
    return digest.hexdigest()


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


def recorded_keys(output_dir: str | Path) -> set[str]:
    """The `run_key`s of the readable batches recorded in `<output_dir>/batches/` (empty: none)."""
    metas = (_meta(f) for f in sorted((Path(output_dir) / RECORDS_DIR).glob("batch_*.npz")))
    return {m["key"] for m in metas if m is not None}


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
        if not resume:
            for f in self.dir.glob("batch_*.npz"):
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

    def render_again(self, videos_dir: Path, rendered: int) -> bool:
        """Whether the recorded batches holding the first `rendered` episodes must run again to render
        their videos (`<videos_dir>/*/eval_episode_<i>.mp4`, lerobot-eval's names): True when one is
        missing or empty, or when episodes past the recorded ones are to be rendered too (a live batch
        would number its videos from 0 again). Sets `live_until` to the batches that then run live."""
        if not self.n_found or rendered <= 0:
            return False
        rows = self.metas[0]["rows"]
        files = [list(Path(videos_dir).glob(f"*/eval_episode_{i}.mp4")) for i in range(rendered)]
        done = rendered <= self.n_found * rows and all(f and f[0].stat().st_size > 0 for f in files)
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

        seeds = None if seeds is None else [int(x) for x in seeds]
        if self.metas[k]["seeds"] != seeds:
            raise ValueError(
                f"Batch {k} in {self.dir} ran env seeds {self.metas[k]['seeds']}, this run gives it {seeds}: "
                "resume with the interrupted run's --eval.batch_size and --seed (and --eval.n_episodes of "
                "at least the batch size), or start over without --ocr.resume=true."
            )
        with np.load(self.dir / self._name(k)) as z:
            meta = json.loads(str(z["meta"]))
            names = [n for n in z.files if n.startswith("rollout.")]
            rollout = {n.split(".", 1)[1]: torch.from_numpy(z[n]) for n in names}
            stats = meta["stats"]
            if stats is not None:
                stats = {**stats, **{n: z.get(f"stats.{n}") for n in _STATS_ARRAYS}}
            set_rng_states({n: z[n] for n in z.files if n.startswith("rng.")})
        return rollout, stats, meta["chunk_steps"]
