"""`lerobot-ocr demo`: a published checkpoint's base and its `ocr_joint` wrapper on the same OOD starts.

The default runs `checkpoints/pusht_cpu` (the checkpoint behind the published Push-T row, committed in
the repository) on the first `DEMO_EPISODES` starts of the test split, the starts of the published row's
first episodes: nothing is trained. It prints the table, and writes the success chart, the density field,
and the videos plus a frame strip of one start where the base fails and `ocr_joint` recovers and finishes.
`--from-scratch` runs the tiny chain instead (demos -> base -> convert -> ocr_joint in minutes), whose
networks are too small to succeed.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

DEMO_EPISODES = 30
CELLS = ("base_ood", "joint_ood")


def demo_split(digest: str) -> str:
    """The starts a checkpoint is shown on: a published checkpoint's (its weights digest in
    `checkpoints/manifest.json`) on the test split, the first starts of its published row; any other on the
    dev split, so that no unpublished network is ever measured on the test starts."""
    from lerobot_ocr.checkpoints import read_manifest

    published = {e["weights_sha256"] for e in read_manifest()["checkpoints"].values()}
    return "test" if digest in published else "dev"


def resolve_checkpoint(task: str, checkpoint: str | Path | None = None) -> Path:
    """The ocr_joint folder to demo: `checkpoint` (a local folder, or a hub id that is in the local hub
    cache or can be downloaded), else the published `checkpoints/<task>_cpu` of this clone, checked
    against its manifest (`checkpoints.published`).

    Raises:
        FileNotFoundError: no such folder, a hub id that cannot be fetched, or no published checkpoint in
            this install (a wheel has none); the message says where to get one.
        ValueError: the published folder differs from its manifest.
    """
    from lerobot_ocr.checkpoints import WHERE_TO_GET, ocr_joint_folder, published

    if checkpoint is None:
        return published(f"{task}_cpu")
    path = Path(checkpoint).expanduser()
    if path.exists():
        return ocr_joint_folder(path)
    repo_id = str(checkpoint)
    if repo_id.count("/") != 1 or repo_id.startswith((".", "/", "~")) or path.parent.is_dir():
        raise FileNotFoundError(
            f"--checkpoint {checkpoint}: no such folder, and not a hub id. {WHERE_TO_GET}"
        )
    from huggingface_hub import snapshot_download

    try:
        folder = snapshot_download(repo_id)
    except Exception as e:  # offline, unknown repo, no access: say so and where to get one
        raise FileNotFoundError(
            f"--checkpoint {repo_id}: could not fetch it from the hub ({type(e).__name__}: {e}). "
            + WHERE_TO_GET
        ) from e
    return ocr_joint_folder(folder)


def solved_per_episode(results: dict, eval_dirs: dict) -> dict[str, list[bool]]:
    """Per cell, each episode's success within one budget every cell reports: the reference's decision
    budget (the paper's joint OOD protocol), else the step budget, else the whole episode. `results`: cell
    -> `summarize` result; `eval_dirs`: cell -> its eval folder (with `episodes.json`)."""
    from lerobot_ocr.eval_report import budget_success

    budgets = {}
    for name, folder in eval_dirs.items():
        episodes = json.loads((Path(folder) / "episodes.json").read_text())
        n = results[name]["n_episodes"]
        budgets[name] = budget_success(episodes, n)
        budgets[name]["episode"] = {"solved": [s > 0 for s in episodes["success_step"][:n]]}
    key = next(k for k in ("reference_budget", "strict", "episode") if all(k in b for b in budgets.values()))
    return {name: b[key]["solved"] for name, b in budgets.items()}


def recovery_example(
    task, checkpoint: Path, solved: dict[str, list[bool]], p: dict, work: Path, split: str, tries: int = 3
) -> dict | None:
    """Videos of one start where the base fails and `ocr_joint` succeeds (`solved`): the cells ran without
    rendering (rendering a batch of envs costs many times their simulation), so each candidate start is run
    again alone, both policies, with its video, under the same protocol; the first of `tries` candidates
    whose re-runs end the same way (the policies' sampling noise differs from the batch's) is kept. Writes
    `<work>/pictures/{base_ood,joint_ood}_episode<i>.mp4` and `recovery_frames.png`. Returns {"episode",
    "seed", "files"}; None when no candidate's re-runs show it."""
    from lerobot_ocr.pipeline import Stages, evaluate_cell
    from lerobot_ocr.plotting import video_frame_strip

    one = {**p, "episodes": 1, "eval_batch": 1, "videos": 1}
    stage, out = Stages(work), work / "pictures"
    candidates = [i for i, (b, j) in enumerate(zip(solved["base_ood"], solved["joint_ood"])) if j and not b]
    for i in candidates[:tries]:
        policies = {"base_ood": checkpoint / "base", "joint_ood": checkpoint}
        results, dirs = {}, {}
        for name, policy in policies.items():
            dirname = f"video_{name}_{i}"
            dirs[name] = work / dirname

            def run(policy=policy, dirname=dirname):
                log = work / "logs" / f"{dirname}.log"
                return evaluate_cell(task, policy, "ood", one, work / dirname, log, split=split, offset=i)

            results[name] = stage(dirname, run)
        again = solved_per_episode(results, dirs)
        if not again["joint_ood"][0] or again["base_ood"][0]:
            continue
        out.mkdir(parents=True, exist_ok=True)
        videos, files = {}, []
        for name, folder in dirs.items():
            videos[name] = folder / "videos" / f"{task.env_type}_0" / "eval_episode_0.mp4"
            files.append(out / f"{name}_episode{i}.mp4")
            shutil.copy(videos[name], files[-1])
        seed = results["joint_ood"]["first_seed"]
        files.append(
            video_frame_strip(
                {"base": videos["base_ood"], "ocr_joint": videos["joint_ood"]},
                out / "recovery_frames.png",
                n_frames=6,
                title=f"Start {seed} (episode {i}): the base fails, ocr_joint recovers and finishes",
            )
        )
        return {"episode": i, "seed": seed, "files": files}
    return None


def demo(
    task: str = "pusht",
    checkpoint: str | Path | None = None,
    workdir: str | Path | None = None,
    episodes: int = DEMO_EPISODES,
    restart: bool = False,
) -> dict:
    """Run the demo (module docstring) into `workdir` (default `outputs/demo_<task>`), resumable per cell;
    a work dir of another checkpoint starts over. Prints the table and the files; returns
    {"results", "checkpoint", "weights_sha256", "example", "files", "seconds"}, also written to
    `<workdir>/demo.json`.

    Raises:
        FileNotFoundError / ValueError: see `resolve_checkpoint`.
        RuntimeError: a cell failed (its log's tail is in the message; a re-run resumes at that cell).
    """
    from lerobot_ocr.checkpoints import weights_digest
    from lerobot_ocr.eval_report import format_start_split, format_table, pair_counts
    from lerobot_ocr.files import clear_workdir
    from lerobot_ocr.pipeline import CHECKPOINT_MARKER, TASKS, WORKDIR_MARKERS, evaluate_checkpoint, pictures

    if task not in TASKS:
        raise ValueError(f"--task must be one of {sorted(TASKS)}, got {task!r}.")
    t = TASKS[task]
    ckpt = resolve_checkpoint(task, checkpoint)
    digest = weights_digest(ckpt)
    work = Path(workdir or f"outputs/demo_{task}").resolve()
    mark = work / CHECKPOINT_MARKER
    before = json.loads(mark.read_text()) if mark.exists() else {}
    if restart or (before and (before["weights_sha256"], before.get("episodes")) != (digest, episodes)):
        clear_workdir(work, WORKDIR_MARKERS)  # the demo's own folder, of another checkpoint or size
    p = {**t.profiles["cpu"], "episodes": episodes, "cells": CELLS, "videos": 0, "progress": True}
    split = demo_split(digest)
    start = time.time()
    print(
        f"{t.title}: the base and ocr_joint of {ckpt} (weights {digest[:12]}) on the first {episodes} OOD "
        f"starts of the {split} split, nothing trained",
        flush=True,
    )
    chain = evaluate_checkpoint(t, ckpt, p, work, split=split)
    files = pictures(t, chain, work / "pictures")
    solved = solved_per_episode(chain.results, chain.eval_dirs)
    example = recovery_example(t, ckpt, solved, p, work, split)
    names = {"base_ood": "base, OOD starts", "joint_ood": "ocr_joint, OOD starts"}
    first = chain.results["joint_ood"]["first_seed"]
    print(f"\n{t.title}, {episodes} OOD starts ({split} split, seeds {first}..{first + episodes - 1}):")
    print(format_table({names[n]: chain.results[n] for n in CELLS}))
    line = format_start_split({names[n]: chain.results[n] for n in CELLS})
    if line:
        print(line)
    c = pair_counts(solved["base_ood"], solved["joint_ood"])
    pair = {"only_joint": c["only_b"], "only_base": c["only_a"], "both": c["both"], "neither": c["neither"]}
    budget = "reference budget" if "success_rate_reference_budget" in chain.results["joint_ood"] else "budget"
    print(
        f"Same starts, within the {budget}: ocr_joint solves {pair['only_joint']} that the base fails, the "
        f"base {pair['only_base']} that ocr_joint fails; both {pair['both']}, neither {pair['neither']}."
    )
    if example is None:
        print(
            "No start here where the base fails and ocr_joint succeeds (again, alone), so no recovery video."
        )
    else:
        files += example["files"]
    seconds = time.time() - start
    print(f"\n{seconds / 60:.1f} min. Pictures and videos:", *files, sep="\n  ")
    print(
        "The published rows (200 starts per cell) and how to run these policies with lerobot-eval: "
        "README.md, 'Results' and 'Try the published policies'."
    )
    summary = {
        "task": task,
        "results": chain.results,
        "checkpoint": str(ckpt),
        "weights_sha256": digest,
        "paired": pair,
        "example": None if example is None else {**example, "files": [str(f) for f in example["files"]]},
        "files": [str(f) for f in files],
        "seconds": seconds,
    }
    (work / "demo.json").write_text(json.dumps(summary, indent=2))
    return summary


def demo_from_scratch(workdir: str | Path = "outputs/demo", restart: bool = False):
    """`lerobot-ocr demo --from-scratch`: the whole Push-T chain at the `demo` size (demos -> base -> convert
    -> ocr_joint -> eval), resumable; its networks are too small to succeed, it shows the steps."""
    from lerobot_ocr.eval_report import format_start_split, format_table
    from lerobot_ocr.files import clear_workdir
    from lerobot_ocr.pipeline import PUSHT, WORKDIR_MARKERS, pictures, run_chain

    work = Path(workdir).resolve()
    if restart:
        clear_workdir(work, WORKDIR_MARKERS)
    start = time.time()
    p = PUSHT.profiles["demo"]
    print(
        f"Push-T from scratch: {p['demos']} demos, a {p['base_steps']}-step base and a {p['ocr_steps']}-step "
        "ocr_joint. These networks are far too small to succeed: this shows every step of the chain, not "
        "a recovery (`lerobot-ocr demo` runs the published checkpoint).",
        flush=True,
    )
    chain = run_chain(PUSHT, p, work)
    files = pictures(PUSHT, chain, work / "pictures")
    print(f"\nPush-T from scratch, tiny CPU-sized networks ({p['episodes']} OOD starts, dev split):")
    print(format_table(chain.results))
    line = format_start_split(chain.results)
    if line:
        print(line)
    print(
        f"\nStages {sum(chain.stage_seconds.values()) / 60:.1f} min (this run "
        f"{(time.time() - start) / 60:.1f} min). Pictures and videos:",
        *files,
        sep="\n  ",
    )
    return chain
