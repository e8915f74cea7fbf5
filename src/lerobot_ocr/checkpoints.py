"""Published checkpoints: the repository's `checkpoints/` folder, its manifest, and how a folder is stored.

A published checkpoint is an `ocr_joint` `pretrained_model` folder as LeRobot saves it (config.json,
model.safetensors, processors, the bundled base in `base/`), weights only. `checkpoints/manifest.json`
lists each one: the sha256 of every file, the digest of its weights, the command and code commit that
produced it, the date, the CPU, and the results file whose rows it backs. `lerobot-eval
--policy.path=checkpoints/<name>` runs it (and `…/<name>/base` the base alone) with no other file.

Large weight tensors are stored in float16 (`store_half`): LeRobot loads them into the float32
parameters of the policy it builds from config.json, so they run in float32; published rows are
measured from exactly these stored weights.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

CHECKPOINTS = Path(__file__).resolve().parents[2] / "checkpoints"  # in a clone; absent from a wheel
MANIFEST = "manifest.json"
HALF_MIN_NUMEL = 1024  # tensors with fewer elements (biases, norms, statistics, thresholds) keep their dtype
WHERE_TO_GET = (
    "The published checkpoints live in the lerobot-ocr repository's `checkpoints/` folder (git clone the "
    "repository; they are committed with their manifest). Pass one with --checkpoint <folder>, or a hub id "
    "of a copy you pushed (`huggingface-cli upload <you>/ocr_joint_pusht checkpoints/pusht_cpu`)."
)


def ocr_joint_folder(folder: Path) -> Path:
    """`folder` resolved, after checking it is an `ocr_joint` `pretrained_model` folder (config.json of type
    ocr_joint) that bundles its base in `base/` (what `OcrJointPolicy.save_pretrained` writes).

    Raises:
        FileNotFoundError: it is not; the message says what to pass instead.
    """
    folder = Path(folder).resolve()
    config = folder / "config.json"
    if not config.is_file() or json.loads(config.read_text()).get("type") != "ocr_joint":
        raise FileNotFoundError(
            f"{folder} is not an ocr_joint pretrained_model folder (no config.json of type ocr_joint): "
            "pass a published checkpoint (checkpoints/<task>_cpu) or a chain's "
            "outputs/<chain>/ocr/checkpoints/last/pretrained_model."
        )
    if not (folder / "base" / "config.json").is_file():
        raise FileNotFoundError(
            f"{folder} has no bundled base in base/: re-save it with OcrJointPolicy.save_pretrained."
        )
    return folder


def sha256_file(path: Path) -> str:
    """sha256 hex of one file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def file_digests(folder: Path) -> dict[str, str]:
    """{path relative to `folder` (posix): sha256} of every file under `folder`, sorted by path."""
    folder = Path(folder)
    return {
        p.relative_to(folder).as_posix(): sha256_file(p) for p in sorted(folder.rglob("*")) if p.is_file()
    }


def weights_digest(folder: Path) -> str:
    """sha256 hex over a checkpoint's `*.safetensors` files (names and bytes, `base/` and the processors'
    normalizer stats included): the trained networks, whatever the config says. The same digest
    `benchmarks/probe.py` keeps beside each probe's episodes.

    Raises:
        ValueError: no weights under `folder`.
    """
    from lerobot_ocr.eval_resume import hash_files

    folder = Path(folder)
    if not any(folder.rglob("*.safetensors")):
        raise ValueError(f"{folder} holds no *.safetensors weights: pass a pretrained_model folder.")
    digest = hashlib.sha256()
    hash_files(digest, folder, "*.safetensors")
    return digest.hexdigest()


def store_half(src: Path, dst: Path, min_numel: int = HALF_MIN_NUMEL) -> dict[str, int]:
    """Write the safetensors file `src` to `dst` with its float32 tensors of at least `min_numel` elements
    in float16 (the networks' weights); every other tensor unchanged. Returns {"halved": n, "kept": m}.

    Raises:
        ValueError: a halved tensor overflows float16 (|x| > 65504): keep that file in float32.
    """
    import torch
    from safetensors.torch import load_file, save_file

    tensors, halved, kept = load_file(str(src)), 0, 0
    for key, t in tensors.items():
        if t.dtype == torch.float32 and t.numel() >= min_numel:
            if t.abs().max() > torch.finfo(torch.float16).max:
                raise ValueError(f"{src}: tensor {key} exceeds the float16 range; keep the file in float32.")
            tensors[key], halved = t.half(), halved + 1
        else:
            kept += 1
    save_file(tensors, str(dst), metadata={"format": "pt"})
    return {"halved": halved, "kept": kept}


def read_manifest(root: Path = CHECKPOINTS) -> dict:
    """`<root>/manifest.json` ({"checkpoints": {name: entry}}); an empty manifest when there is none."""
    path = Path(root) / MANIFEST
    return json.loads(path.read_text()) if path.is_file() else {"checkpoints": {}}


def verify(folder: Path, entry: dict) -> list[str]:
    """What differs between `folder` and its manifest `entry`: one line per missing, extra or changed file
    (an empty list: every file's sha256 matches)."""
    have, want = file_digests(folder), entry["files"]
    problems = [f"missing {name}" for name in want if name not in have]
    problems += [f"not in the manifest: {name}" for name in have if name not in want]
    problems += [
        f"changed {name} (sha256 {have[name][:12]}…, manifest {want[name][:12]}…)"
        for name in want
        if name in have and have[name] != want[name]
    ]
    return problems


def published(name: str, root: Path = CHECKPOINTS) -> Path:
    """The folder of published checkpoint `name` (e.g. `pusht_cpu`), checked against the manifest.

    Raises:
        FileNotFoundError: no such checkpoint here (an installed wheel has none; the message says where
            to get one).
        ValueError: its files differ from the manifest (the message lists them).
    """
    entry = read_manifest(root)["checkpoints"].get(name)
    folder = Path(root) / name
    if entry is None or not folder.is_dir():
        raise FileNotFoundError(f"No published checkpoint {name!r} under {root}. {WHERE_TO_GET}")
    problems = verify(folder, entry)
    if problems:
        raise ValueError(
            f"{folder} differs from {Path(root) / MANIFEST}: " + "; ".join(problems[:5]) + ". Restore it "
            f"with `git checkout -- {folder}` (or republish it with benchmarks/publish_checkpoint.py)."
        )
    return folder
