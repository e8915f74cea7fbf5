"""Per-batch records of a `lerobot-ocr eval` run, so that an interrupted run resumes where it stopped.

lerobot-eval runs its episodes batch after batch (`--eval.batch_size` envs each, env seeds
`--seed` + episode index) and writes nothing until the last one. `run_eval` records each finished
batch in `<output_dir>/batches/batch_<k>.npz`: the rollout's tensors (`reward`, `success`, `done`:
(B, T); `action`: (B, T, A)), ocr_joint's `ocr_stats()` for it, the actions per decision of a chunking
policy, and the RNG states (torch CPU and CUDA, NumPy, Python) right after it. A run with
`--ocr.resume=true` and the same arguments and checkpoint replays the batches it finds instead of
simulating them, then sets the RNG states the last one left: the episodes after it are the ones the
uninterrupted run would have had (bit for bit on CPU, where torch's kernels are deterministic).
Writing a record takes milliseconds; one process, so none of the ≈ 80 s that an extra eval process
costs on Square (`benchmarks/EXPERIMENTS.md`, "Resumable eval cells in chunks").

Our own: lerobot-eval has no resume, and `lerobot-train --resume` covers training only.
"""

from __future__ import annotations

import hashlib
import json
import os
import random
from pathlib import Path

import numpy as np

RECORDS_DIR = "batches"
# flags that do not change a batch's episodes: how many batches run, where, which are rendered, resuming
_KEY_IGNORES = ("eval.n_episodes", "output_dir", "ocr.videos", "ocr.resume")
_STATS_ARRAYS = ("score", "in_recovery", "decisions")


def run_key(args: list[str]) -> str:
    """The identity of a run's batches: its arguments (those that change episodes) and its checkpoint.

    `args`: the eval's CLI strings (`lerobot-ocr eval`'s, ours included). The `--policy.path` folder
    (the last one given) is hashed file by file (names and bytes: a retrained checkpoint under the same
    path is another run); a hub id counts as its string.
    """
    kept = sorted(a for a in args if not any(a.startswith(f"--{flag}=") for flag in _KEY_IGNORES))
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


def recorded_keys(output_dir: str | Path) -> set[str]:
    """The `run_key`s of the batches recorded in `<output_dir>/batches/` (empty: none)."""
    keys = set()
    for f in sorted((Path(output_dir) / RECORDS_DIR).glob("batch_*.npz")):
        with np.load(f) as z:
            keys.add(json.loads(str(z["meta"]))["key"])
    return keys


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
        # batches 0..n-1 without a gap: only a prefix can be replayed in seed order
        self.n_found = 0
        while (self.dir / self._name(self.n_found)).exists():
            self.n_found += 1

    @staticmethod
    def _name(k: int) -> str:
        return f"batch_{k:05d}.npz"

    def save(self, k: int, rollout: dict, stats: dict | None, chunk_steps: int | None) -> None:
        """Record batch `k`: `rollout` (lerobot's rollout dict, tensors), `stats` (ocr_joint's
        `ocr_stats()` for it, or None), and the current RNG states. Atomic: a temp file, then a rename."""
        import torch

        # the tensors lerobot-eval reads (observations, only returned for online training, are not kept)
        arrays = {f"rollout.{n}": t.detach().cpu().numpy() for n, t in rollout.items() if torch.is_tensor(t)}
        scalars = None
        if stats is not None:
            scalars = {k_: v for k_, v in stats.items() if k_ not in _STATS_ARRAYS}
            for name in _STATS_ARRAYS:
                if stats.get(name) is not None:
                    arrays[f"stats.{name}"] = np.asarray(stats[name])
        meta = {"key": self.key, "batch": k, "chunk_steps": chunk_steps, "stats": scalars}
        self.dir.mkdir(parents=True, exist_ok=True)
        tmp = self.dir / f".{self._name(k)}.tmp"
        with open(tmp, "wb") as f:
            np.savez(f, meta=np.asarray(json.dumps(meta)), **arrays, **rng_states())
        os.replace(tmp, self.dir / self._name(k))

    def load(self, k: int) -> tuple[dict, dict | None, int | None]:
        """Replay batch `k`: set the RNG states recorded after it; return (rollout tensors, ocr stats or
        None, actions per decision). Raises FileNotFoundError for a batch not recorded."""
        import torch

        with np.load(self.dir / self._name(k)) as z:
            meta = json.loads(str(z["meta"]))
            names = [n for n in z.files if n.startswith("rollout.")]
            rollout = {n.split(".", 1)[1]: torch.from_numpy(z[n]) for n in names}
            stats = meta["stats"]
            if stats is not None:
                stats = {**stats, **{n: z.get(f"stats.{n}") for n in _STATS_ARRAYS}}
            set_rng_states({n: z[n] for n in z.files if n.startswith("rng.")})
        return rollout, stats, meta["chunk_steps"]
