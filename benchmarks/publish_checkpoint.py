"""Publish a finished chain's `ocr_joint` checkpoint into `checkpoints/`, or keep a long run's progress.

    # publish (the row is then measured from the stored copy: `pusht_ocr.py --from-checkpoint …`)
    .venv/bin/python benchmarks/publish_checkpoint.py pusht_cpu \
        --source outputs/pusht_ocr_cpu/ocr/checkpoints/last/pretrained_model --row pusht_cpu
    # a training run that cannot finish in one session: keep its last checkpoint (weights and optimizer)
    .venv/bin/python benchmarks/publish_checkpoint.py pusht_cpu_base --in-progress \
        --source outputs/pusht_ocr_cpu/base/checkpoints/last
    # … and on the next machine, put it back where the chain resumes from
    .venv/bin/python benchmarks/publish_checkpoint.py pusht_cpu_base --restore outputs/pusht_ocr_cpu/base

Publishing copies the `pretrained_model` folder (its bundled `base/` included, no `training_state/`),
stores the networks' large tensors in float16 (`lerobot_ocr.checkpoints.store_half`), drops the
machine-local `base_path` from config.json (the base is bundled), and writes the manifest entry
(`checkpoints/manifest.json`, rendered to `checkpoints/README.md`): sha256 of every file, the weights
digest, the command and code commit that produced it (the source checkout's HEAD), the date, the CPU and
the results file whose rows it backs. An existing checkpoint is replaced only with `--replace` (git keeps
every version; replace one only when a new row is published from it).

An in-progress entry (`checkpoints/in_progress/<name>/`) is a training checkpoint as LeRobot wrote it
(fp32 weights and optimizer state: a resume continues exactly), listed in the manifest's `in_progress`;
delete it (`--drop`) once the run has finished and its result is published.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(REPO / "src")]
from lerobot_ocr.checkpoints import (  # noqa: E402
    MANIFEST,
    file_digests,
    ocr_joint_folder,
    read_manifest,
    store_half,
    weights_digest,
)

ROOT = REPO / "checkpoints"
NETWORK_FILE = "model.safetensors"  # the policy's own weights (the processors' stats stay as trained)


def cpu_model() -> str:
    """This machine's CPU model name and core count (`/proc/cpuinfo`)."""
    import os

    name = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{name}, {os.cpu_count()} cores"


def git_commit(path: Path) -> str:
    """HEAD of the git checkout holding `path` (the code that trained it), '+dirty' when it had changes."""
    folder = path if path.is_dir() else path.parent
    try:
        head = subprocess.run(
            ["git", "-C", str(folder), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(folder), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def source_checkout(source: Path) -> Path:
    """The folder whose git HEAD trained `source`: the chain's work dir lives in `<checkout>/outputs/`."""
    for parent in source.resolve().parents:
        if parent.name == "outputs":
            return parent.parent
    return source


def publish(
    name: str,
    source: Path,
    row: str,
    command: str,
    root: Path = ROOT,
    replace: bool = False,
    commit: str | None = None,
) -> dict:
    """Copy the ocr_joint `pretrained_model` folder `source` to `<root>/<name>` in the published form and
    write its manifest entry. Returns the entry.

    Raises:
        FileNotFoundError: `source` is not an ocr_joint folder with its base bundled in `base/`.
        FileExistsError: `<root>/<name>` exists and `replace` is False.
    """
    source = ocr_joint_folder(source)
    dst = root / name
    if dst.exists() and not replace:
        raise FileExistsError(
            f"{dst} is published already; pass --replace only when a new row is published from it."
        )
    tmp = root / f".{name}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(source, tmp, ignore=shutil.ignore_patterns("training_state"))
    halved = {}
    for f in sorted(tmp.rglob(NETWORK_FILE)):
        halved[f.relative_to(tmp).as_posix()] = store_half(f, f)
    cfg = json.loads((tmp / "config.json").read_text())
    source_base = cfg.get("base_path")
    cfg["base_path"] = None  # bundled in base/; the training machine's path is in the manifest
    (tmp / "config.json").write_text(json.dumps(cfg, indent=4) + "\n")
    if dst.exists():
        shutil.rmtree(dst)
    tmp.rename(dst)
    entry = {
        "kind": "ocr_joint pretrained_model (base bundled in base/)",
        "row": f"benchmarks/results/{row}.json" if row else None,
        "command": command,
        "code_commit": commit or git_commit(source_checkout(source)),
        "date": dt.date.today().isoformat(),
        "cpu": cpu_model(),
        "source": str(source),
        "source_base_path": source_base,
        "source_weights_sha256": weights_digest(source),
        "storage": "tensors of >= 1024 elements in model.safetensors stored in float16 (loaded into float32 "
        "parameters); everything else as trained. Rows are measured from these stored weights.",
        "halved": halved,
        "weights_sha256": weights_digest(dst),
        "bytes": sum(p.stat().st_size for p in dst.rglob("*") if p.is_file()),
        "files": file_digests(dst),
    }
    write_entry(root, "checkpoints", name, entry)
    return entry


def keep_in_progress(name: str, source: Path, note: str, root: Path = ROOT) -> dict:
    """Copy a training checkpoint folder (`<out>/checkpoints/<step>`: pretrained_model + training_state)
    unchanged to `<root>/in_progress/<name>/<step>` and list it in the manifest's `in_progress`."""
    source = Path(source).resolve()
    if not (source / "training_state").is_dir():
        raise FileNotFoundError(f"{source} is not a training checkpoint (no training_state/).")
    dst = root / "in_progress" / name
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(source, dst / source.name)
    entry = {
        "step": source.name,
        "note": note,
        "code_commit": git_commit(source_checkout(source)),
        "date": dt.date.today().isoformat(),
        "cpu": cpu_model(),
        "source": str(source),
        "bytes": sum(p.stat().st_size for p in dst.rglob("*") if p.is_file()),
        "files": file_digests(dst),
    }
    write_entry(root, "in_progress", name, entry)
    return entry


def restore(name: str, out: Path, root: Path = ROOT) -> Path:
    """Put in-progress checkpoint `name` back as `<out>/checkpoints/<step>` with the `last` link LeRobot
    resumes from (`out`: the training stage's output dir, e.g. outputs/pusht_ocr_cpu/base). Returns it."""
    entry = read_manifest(root).get("in_progress", {}).get(name)
    if entry is None:
        raise FileNotFoundError(f"No in-progress checkpoint {name!r} in {root / MANIFEST}.")
    src = root / "in_progress" / name / entry["step"]
    dst = Path(out) / "checkpoints" / entry["step"]
    if dst.exists():
        raise FileExistsError(f"{dst} exists: the run is there already (resume it as it is).")
    shutil.copytree(src, dst)
    last = dst.parent / "last"
    if last.is_symlink() or last.exists():
        last.unlink()
    last.symlink_to(entry["step"])
    return dst


def write_entry(root: Path, section: str, name: str, entry: dict | None) -> None:
    """Set (None: delete) `name` in the manifest's `section` and re-render checkpoints/README.md."""
    manifest = read_manifest(root)
    manifest.setdefault("checkpoints", {})
    manifest.setdefault("in_progress", {})
    if entry is None:
        manifest[section].pop(name, None)
    else:
        manifest[section][name] = entry
    root.mkdir(parents=True, exist_ok=True)
    (root / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    (root / "README.md").write_text(render(manifest))


def render(manifest: dict) -> str:
    """checkpoints/README.md from the manifest."""
    lines = [
        "# Published checkpoints",
        "",
        "Written by `benchmarks/publish_checkpoint.py` from `manifest.json` (the machine-readable record: "
        "sha256 of every file). Each folder is an `ocr_joint` `pretrained_model` as LeRobot saves it, its "
        "base bundled in `base/`, weights only; `tests/test_published_checkpoints.py` checks every digest "
        "and runs one episode of each.",
        "",
        "```bash",
        "lerobot-eval --policy.path=checkpoints/pusht_cpu --env.type=pusht_ocr --env.region=ood \\",
        "  --env.obs_type=environment_state_agent_pos --eval.n_episodes=10 --eval.batch_size=10",
        "lerobot-eval --policy.path=checkpoints/pusht_cpu/base ...   # the base alone",
        "```",
        "",
        "| checkpoint | row it backs | weights sha256 | size | code commit | date | CPU | command |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, e in sorted(manifest.get("checkpoints", {}).items()):
        lines.append(
            f"| `{name}` | `{e['row']}` | `{e['weights_sha256'][:16]}` | {e['bytes'] / 1e6:.1f} MB | "
            f"`{e['code_commit'][:12]}` | {e['date']} | {e['cpu']} | `{e['command']}` |"
        )
    lines += ["", "Storage: " + next(iter(manifest.get("checkpoints", {}).values()), {}).get("storage", "—")]
    if manifest.get("in_progress"):
        lines += [
            "",
            "## In progress",
            "",
            "Training checkpoints of runs that could not finish in one session (fp32 weights and optimizer "
            "state, so the resume is exact). Put one back with `benchmarks/publish_checkpoint.py <name> "
            "--restore <training output dir>`, then re-run the chain's command.",
            "",
            "| name | step | note | code commit | date | CPU | size |",
            "|---|---|---|---|---|---|---|",
        ]
        for name, e in sorted(manifest["in_progress"].items()):
            lines.append(
                f"| `{name}` | {e['step']} | {e['note']} | `{e['code_commit'][:12]}` | {e['date']} | "
                f"{e['cpu']} | {e['bytes'] / 1e6:.1f} MB |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", help="checkpoint name, e.g. pusht_cpu (folder checkpoints/<name>)")
    parser.add_argument("--source", help="the pretrained_model folder (or, --in-progress, a step folder)")
    parser.add_argument("--row", default=None, help="results file stem whose rows it backs, e.g. pusht_cpu")
    parser.add_argument("--command", default=None, help="the command that trained it (default: the chain's)")
    parser.add_argument("--replace", action="store_true", help="replace a published checkpoint")
    parser.add_argument("--in-progress", action="store_true", help="keep a training checkpoint to resume")
    parser.add_argument("--note", default="", help="--in-progress: what the run is and what is left")
    parser.add_argument("--restore", metavar="OUT", help="put in-progress <name> back into OUT/checkpoints")
    parser.add_argument("--drop", action="store_true", help="remove in-progress <name> (its run finished)")
    args = parser.parse_args()
    try:
        if args.restore:
            print(restore(args.name, Path(args.restore)))
        elif args.drop:
            shutil.rmtree(ROOT / "in_progress" / args.name, ignore_errors=True)
            write_entry(ROOT, "in_progress", args.name, None)
        elif args.in_progress:
            if not args.source:
                parser.error("--in-progress needs --source <out>/checkpoints/<step>")
            e = keep_in_progress(args.name, Path(args.source), args.note)
            print(f"kept {args.name} step {e['step']} ({e['bytes'] / 1e6:.1f} MB)")
        else:
            if not args.source:
                parser.error("--source <pretrained_model folder> is required to publish")
            task = args.name.split("_")[0]
            command = args.command or f".venv/bin/python benchmarks/{task}_ocr.py --profile cpu"
            e = publish(args.name, Path(args.source), args.row or args.name, command, replace=args.replace)
            print(f"published {args.name}: {e['bytes'] / 1e6:.1f} MB, weights {e['weights_sha256'][:16]}")
    except (FileNotFoundError, FileExistsError, ValueError) as e:
        parser.error(str(e))


if __name__ == "__main__":
    main()
