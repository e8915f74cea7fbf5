"""The `gpu` row: the Push-T low-dim base trained with Diffusion Policy's own low-dim recipe on a GPU for a
few minutes, then evaluated here on CPU beside the `cpu` row (same data, seeds and protocol).

    .venv/bin/python benchmarks/gpu_base.py pack                       # here: items + packages -> .gpu/
    python3 benchmarks/gpu_base.py train --seconds 420 --out "$OUT"    # on the GPU machine (bare torch)
    .venv/bin/python benchmarks/gpu_base.py evaluate --weights <dir>   # here: checkpoint, 4 cells, JSON

and the paper's Table III on that row (after `evaluate`):

    .venv/bin/python benchmarks/gpu_base.py continual-pack             # here: collect, merge, pack -> .gpu/
    python3 benchmarks/gpu_base.py train --steps <the gpu base's> --out "$OUT"   # on the GPU machine
    .venv/bin/python benchmarks/gpu_base.py continual-evaluate --weights <dir>   # here: 4 cells, JSON

The recipe (Chi et al. 2023, low-dim Push-T) with a U-Net half as wide, (128, 256, 512), whose fp16
weights fit what the GPU machine sends back (its (256, 512, 1024) does not); batch 256, AdamW 1e-4 (betas
0.95, 0.999, weight decay 1e-6), cosine schedule with 500 warm-up steps, EMA weights (power 0.75, at most
0.9999) through torch's `AveragedModel`; the model, its loss and the noise scheduler are LeRobot's
`DiffusionPolicy`, so the checkpoint is a plain LeRobot one. The step count is `--steps`, or what fits in
`--seconds` (measured on the machine first); the cosine schedule spans exactly those steps.

`pack` computes every training item once with LeRobot's dataset, sampler rule (`drop_n_last_frames`) and
preprocessor (normalisation), so the GPU machine needs only torch and LeRobot's pure-Python packages,
which `pack` copies into `.gpu/site` (the GPU image has torch, numpy, huggingface_hub; no LeRobot).
`evaluate` wraps the new base with the inverse policy of a finished `cpu`-profile chain (`lerobot-ocr
rebase`) and runs the four cells of `benchmarks/pusht_ocr.py` (resumable), writing
`benchmarks/results/pusht_gpu.json` and RESULTS.md's "Push-T (gpu)" section. `continual-pack` has the
row's joint policy collect OOD episodes (`benchmarks/continual.py`'s stage), merges them with the demos and
packs the merged data into `.gpu/` (replacing the base's pack); `continual-evaluate` checks that the weights
were trained exactly like the gpu base but on that pack, so the gpu base is the control.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
# results_md, continual and lerobot_ocr, imported lazily (the GPU machine needs none of them)
sys.path[:0] = [str(HERE), str(REPO / "src")]
PACK = REPO / ".gpu"
# LeRobot's import chain on the GPU image lacks these (the image has torch, numpy, huggingface_hub, …).
PACKAGES = (
    "lerobot",
    "datasets",
    "diffusers",
    "draccus",
    "gymnasium",
    "farama_notifications",
    "mergedeep",
    "dill",
    "multiprocess",
    "_multiprocess",
    "pytz",
    "toml",
)
# Diffusion Policy's U-Net is (256, 512, 1024): 63.5 M parameters, 121 MiB even in fp16, more than the GPU
# machine can send back (64 MiB). (128, 256, 512) is 16.6 M, 32 MiB in fp16, sent as 15 MiB shards.
SHARD_BYTES = 15 * 2**20
RECIPE = {
    "down_dims": (128, 256, 512),
    "batch": 256,
    "lr": 1e-4,
    "betas": (0.95, 0.999),
    "weight_decay": 1e-6,
    "warmup": 500,
    "ema_power": 0.75,
    "ema_max": 0.9999,
    "seed": 1000,
}


def base_config(meta):
    """The base's DiffusionConfig: the `cpu` row's settings with the recipe's U-Net, features from `meta`."""
    from lerobot.configs.types import FeatureType, NormalizationMode
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.utils.feature_utils import dataset_to_policy_features

    minmax = NormalizationMode.MIN_MAX
    cfg = DiffusionConfig(
        device="cpu",
        push_to_hub=False,
        down_dims=RECIPE["down_dims"],
        horizon=16,
        n_action_steps=8,
        n_obs_steps=2,
        noise_scheduler_type="DDIM",
        num_inference_steps=10,
        normalization_mapping={
            "VISUAL": NormalizationMode.MEAN_STD,
            "STATE": minmax,
            "ENV": minmax,
            "ACTION": minmax,
        },
    )
    features = dataset_to_policy_features(meta.features)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    return cfg


def pack(data: Path, repo_id: str = "local/pusht_base", out: Path = PACK) -> None:
    """Write `out/items.pt` (every normalised training item of the dataset at `data`, normalised with its
    own statistics), `out/config/config.json` and `out/site`."""
    import torch
    from lerobot.datasets import EpisodeAwareSampler, LeRobotDataset
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.policies.factory import make_pre_post_processors

    from lerobot_ocr.train_in_memory import cache_items

    meta = LeRobotDataset(repo_id, root=data).meta
    cfg = base_config(meta)
    ds = LeRobotDataset(repo_id, root=data, delta_timestamps=resolve_delta_timestamps(cfg, meta))
    sampler = EpisodeAwareSampler(
        ds.meta.episodes["dataset_from_index"],
        ds.meta.episodes["dataset_to_index"],
        drop_n_last_frames=cfg.drop_n_last_frames,
    )
    indices = sorted(iter(sampler))
    cached = cache_items(ds)
    items = [cached[i] for i in indices]
    keys = [
        k
        for k, v in items[0].items()
        if isinstance(v, torch.Tensor) and (k.startswith("observation.") or k.startswith("action"))
    ]
    batch = {k: torch.stack([it[k] for it in items]) for k in keys}
    preprocessor, _ = make_pre_post_processors(cfg, dataset_stats=ds.meta.stats)
    batch = preprocessor(batch)
    batch = {k: v.cpu() for k, v in batch.items() if isinstance(v, torch.Tensor)}
    shutil.rmtree(out, ignore_errors=True)
    (out / "config").mkdir(parents=True)
    torch.save(batch, out / "items.pt")
    cfg.save_pretrained(out / "config")
    (out / "source.json").write_text(json.dumps({"data": str(data.resolve()), "items": len(indices)}))
    site = Path(next(p for p in sys.path if p.endswith("site-packages")))
    for name in PACKAGES:
        for src in [site / name, *site.glob(f"{name}-*.dist-info")]:
            if src.is_dir():
                shutil.copytree(src, out / "site" / src.name, ignore=shutil.ignore_patterns("__pycache__"))
    for src in site.glob("av-*.dist-info"):  # its metadata only: LeRobot checks av's version at import
        shutil.copytree(src, out / "site" / src.name)
    for py in ("mergedeep.py",):
        if (site / py).is_file():
            shutil.copy(site / py, out / "site" / py)
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    print(f"packed {len(indices)} items, keys {sorted(batch)}, {size / 2**20:.1f} MiB in {out}")


def _import_lerobot(site: Path) -> None:
    """Make LeRobot importable on the GPU image: our copies after its own packages; PyAV stubbed (only
    video decoding needs it, and this script decodes no video)."""
    import importlib.machinery

    sys.path.append(str(site))
    try:
        import av  # noqa: F401
    except ImportError:

        class _Stub(type):  # any attribute is another stub class (so `av.codec.Codec | None` works)
            def __getattr__(cls, name):
                if name.startswith("__"):
                    raise AttributeError(name)
                return _Stub(f"{cls.__name__}.{name}", (), {})

        for name in ("av", "av.logging", "av.video", "av.audio", "av.container", "av.codec", "av.error"):
            sys.modules[name] = _Stub(name, (), {"__spec__": importlib.machinery.ModuleSpec(name, None)})


def train(pack_dir: Path, seconds: float, out: Path, steps: int | None = None) -> None:
    """Train the base for about `seconds` on the GPU (or exactly `steps` steps); write to `out` its
    config.json, its EMA weights as fp16 shards `ema_fp16_<i>.safetensors` (refreshed every minute, so a
    cut run still returns them) and train_log.json."""
    t0 = time.time()
    _import_lerobot(pack_dir / "site")
    import torch
    from diffusers.optimization import get_cosine_schedule_with_warmup
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from torch.optim.swa_utils import AveragedModel

    torch.backends.cuda.matmul.allow_tf32 = True
    torch.backends.cudnn.allow_tf32 = True
    device = "cuda" if torch.cuda.is_available() else "cpu"  # cpu: a smoke test of this script only
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    cfg = PreTrainedConfig.from_pretrained(pack_dir / "config")
    cfg.device = device
    data = {k: v.to(device) for k, v in torch.load(pack_dir / "items.pt").items()}
    pack_source = json.loads((pack_dir / "source.json").read_text())
    n = len(next(iter(data.values())))
    batch_size = RECIPE["batch"]

    def ema_update(averaged, current, num_averaged):  # Diffusion Policy's EMA warm-up (power 0.75)
        step = int(num_averaged)
        decay = min(RECIPE["ema_max"], max(0.0, 1 - (1 + step) ** -RECIPE["ema_power"]))
        torch._foreach_lerp_(averaged, current, 1 - decay)

    def build():
        torch.manual_seed(RECIPE["seed"])
        policy = DiffusionPolicy(cfg).to(device).train()
        optimizer = torch.optim.AdamW(
            policy.parameters(),
            lr=RECIPE["lr"],
            betas=RECIPE["betas"],
            eps=1e-8,
            weight_decay=RECIPE["weight_decay"],
        )
        return policy, optimizer

    def step_fn(policy, optimizer, idx):
        loss, _ = policy.forward({k: v[idx] for k, v in data.items()})
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 10.0)  # lerobot-train's diffusion preset
        optimizer.step()
        return loss

    warm, probe = (30, 100) if device == "cuda" else (1, 2)
    # 1. measure this machine's step rate (a throw-away model), 2. train for the time that is left
    policy, optimizer = build()
    ema = AveragedModel(policy, multi_avg_fn=ema_update, use_buffers=True)
    for i in range(warm + probe):
        if i == warm:
            sync()
            t_probe = time.time()
        step_fn(policy, optimizer, torch.randint(0, n, (batch_size,), device=device))
        ema.update_parameters(policy)
    sync()
    rate = probe / (time.time() - t_probe)
    steps_asked = steps
    steps = steps or max(1, int(rate * (seconds - (time.time() - t0) - 20)))
    print(f"{rate:.1f} steps/s -> {steps} steps (≈ {steps / rate:.0f} s)", flush=True)

    policy, optimizer = build()
    scheduler = get_cosine_schedule_with_warmup(optimizer, RECIPE["warmup"], steps)
    ema = AveragedModel(policy, multi_avg_fn=ema_update, use_buffers=True)
    log, losses, last_save, t_train = [], [], time.time(), time.time()
    gen = torch.Generator(device=device).manual_seed(RECIPE["seed"])
    perm, pos = torch.randperm(n, device=device, generator=gen), 0

    def save(step):  # EMA weights in fp16 shards of at most SHARD_BYTES (the device tool's file limit)
        from safetensors.torch import save_file

        state = {
            k: v.detach().to(torch.float16 if v.is_floating_point() else v.dtype).cpu()
            for k, v in ema.module.state_dict().items()
        }
        shards, size = [{}], 0
        for k, v in state.items():
            if size + v.nbytes > SHARD_BYTES and shards[-1]:
                shards, size = [*shards, {}], 0
            shards[-1][k], size = v.contiguous(), size + v.nbytes
        for old in out.glob("ema_fp16_*.safetensors"):
            old.unlink()
        for i, shard in enumerate(shards):
            save_file(shard, out / f"ema_fp16_{i}.safetensors")
        cfg.save_pretrained(out)
        info = {
            "recipe": RECIPE,
            "seconds_asked": None if steps_asked else seconds,
            "steps_asked": steps_asked,
            "steps_planned": steps,
            "steps_done": step,
            "items": n,
            "data": pack_source.get("data"),
            "train_seconds": time.time() - t_train,
            "steps_per_second_probe": rate,
            "gpu": torch.cuda.get_device_name() if device == "cuda" else "cpu",
            "torch": torch.__version__,
            "log": log,
        }
        (out / "train_log.json").write_text(json.dumps(info, indent=1))

    for step in range(1, steps + 1):
        if pos + batch_size > n:  # a new epoch: reshuffle (the last partial batch is dropped)
            perm, pos = torch.randperm(n, device=device, generator=gen), 0
        losses.append(step_fn(policy, optimizer, perm[pos : pos + batch_size]).detach())
        pos += batch_size
        scheduler.step()
        ema.update_parameters(policy)
        if step % 1000 == 0 or step == steps:
            log.append(
                {
                    "step": step,
                    "loss": torch.stack(losses).mean().item(),
                    "lr": scheduler.get_last_lr()[0],
                    "seconds": round(time.time() - t_train, 1),
                }
            )
            losses = []
            print(log[-1], flush=True)
            if time.time() - last_save > 60:
                save(step)
                last_save = time.time()
    save(steps)
    print(f"done: {steps} steps in {time.time() - t_train:.0f} s", flush=True)


def check_trained_on(train_log: dict, data: Path, cfg) -> None:
    """Raise SystemExit unless `train_log`'s weights were trained on the items of the dataset at `data`: the
    pack's dataset path when recorded, and always the item count (frames less `drop_n_last_frames` per
    episode), since the checkpoint gets `data`'s statistics."""
    info = json.loads((data / "meta" / "info.json").read_text())
    items = info["total_frames"] - info["total_episodes"] * cfg.drop_n_last_frames
    recorded = train_log.get("data")
    if train_log["items"] != items or (recorded and Path(recorded).resolve() != data.resolve()):
        raise SystemExit(
            f"These weights were trained on {train_log['items']} items ({recorded or 'data not recorded'}), "
            f"not on {data} ({items} items): pack that dataset and train again (a stale .gpu/ pack?)."
        )


def assemble_checkpoint(weights: Path, out: Path, data: Path, repo_id: str) -> None:
    """A LeRobot `DiffusionPolicy` checkpoint in `out` from the train command's folder `weights` (config and
    fp16 EMA shards, loaded back as fp32), with pre/post-processors from the statistics of the dataset at
    `data`, which must be the one `pack` made the items from (else SystemExit)."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from lerobot.policies.factory import make_pre_post_processors
    from safetensors.torch import load_file

    cfg = PreTrainedConfig.from_pretrained(weights)
    cfg.device = "cpu"
    check_trained_on(json.loads((weights / "train_log.json").read_text()), data, cfg)
    policy = DiffusionPolicy(cfg)
    state = {}
    for shard in sorted(weights.glob("ema_fp16_*.safetensors")):
        state.update(load_file(shard))
    policy.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state.items()})
    shutil.rmtree(out, ignore_errors=True)
    policy.save_pretrained(out)
    meta = LeRobotDatasetMetadata(repo_id, root=data)
    for processor in make_pre_post_processors(cfg, dataset_stats=meta.stats):
        processor.save_pretrained(out)


def row_settings(p: dict, train_log: dict, source_train: dict) -> dict:
    """The gpu row's settings: the `cpu` profile's `p`, with the recipe's base (`train_log`: its steps) and
    the inverse policy of the source chain (`source_train`: its lerobot-train config)."""
    return {
        **p,
        "base_dims": str(list(RECIPE["down_dims"])),
        "base_steps": train_log["steps_done"],
        "base_batch": RECIPE["batch"],
        "ocr_steps": source_train["steps"],
        "ocr_dims": str(source_train["policy"]["down_dims"]),
    }


def evaluate(
    weights: Path, source: Path, work: Path, cells: list[str], eval_batch: int | None = None
) -> None:
    """Assemble the gpu base checkpoint (+ processors from the dataset's stats) in `work`, wrap it with
    `source`'s inverse policy, run the cells (resumable) and publish the row."""
    from results_md import update_section
    from summary import write as write_summary

    from lerobot_ocr.eval_report import format_table
    from lerobot_ocr.pipeline import BIN, EVAL_SEED, PUSHT, Stages, chain_cells, evaluate_cells, run

    p = _cpu_profile(eval_batch)
    stage = Stages(work)
    base = work / "base" / "checkpoints" / "last" / "pretrained_model"
    joint = work / "ocr" / "checkpoints" / "last" / "pretrained_model"
    source_joint = source / "ocr" / "checkpoints" / "last" / "pretrained_model"
    train_log = _same_weights(weights, work / "train_log.json")

    def assemble():
        assemble_checkpoint(weights, base, source / "base_data", "local/pusht_base")
        (work / "train_log.json").write_text(json.dumps(train_log, indent=1))
        shutil.rmtree(joint, ignore_errors=True)
        run(
            [
                str(BIN / "lerobot-ocr"),
                "rebase",
                f"--policy-path={source_joint}",
                f"--base-path={base}",
                f"--output-dir={joint}",
            ],
            work / "logs" / "rebase.log",
        )
        return {"steps": train_log["steps_done"], "inverse_policy_from": str(source_joint)}

    stage("assemble", assemble)
    results = evaluate_cells(stage, PUSHT, chain_cells(base, joint, cells), p)
    table = format_table(results)
    print("\n" + table)
    if set(results) != {"base_id", "base_ood", "joint_id", "joint_ood"}:
        return  # the row is published once all four cells exist
    source_train = json.loads(
        (source / "ocr" / "checkpoints" / "last" / "pretrained_model" / "train_config.json").read_text()
    )
    payload = {
        "benchmark": "pusht_ocr",
        "profile": "gpu",
        "settings": row_settings(p, train_log, source_train),
        "recipe": RECIPE,
        "base_training": {k: train_log[k] for k in ("steps_done", "train_seconds", "gpu", "torch", "items")},
        **results,
        "stage_seconds": stage.times,
        "machine": f"eval: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}",
        "date": dt.date.today().isoformat(),
    }
    (HERE / "results" / "pusht_gpu.json").write_text(json.dumps(payload, indent=2) + "\n")
    write_summary()
    minutes = train_log["train_seconds"] / 60
    batch_flag = f" --eval-batch {eval_batch}" if eval_batch else ""
    update_section(
        "Push-T (gpu)",
        f"""
The `cpu` row's 100 scripted ID demos and low-dim features; base trained with Diffusion Policy's
low-dim recipe on one {train_log["gpu"]}: U-Net {list(RECIPE["down_dims"])}, batch {RECIPE["batch"]},
{train_log["steps_done"]} steps in {minutes:.1f} min, AdamW 1e-4, cosine with 500 warm-up steps, EMA
weights (power 0.75); the inverse policy of the chain in `{source}` ({source_train["steps"]} steps,
U-Net {source_train["policy"]["down_dims"]}), joined with `lerobot-ocr rebase`. {p["episodes"]} episodes
per cell, env seeds {EVAL_SEED}+i, evaluated on CPU; {PUSHT.episode_length}-step episodes, success within
{PUSHT.step_budget} steps (strict) and within {PUSHT.decision_budget} policy decisions.

{table}

Machine: {payload["machine"]}. Date: {payload["date"]}.

Commands: `.venv/bin/python benchmarks/gpu_base.py pack --workdir {source}`; on the GPU machine
`python3 benchmarks/gpu_base.py train --seconds {train_log.get("seconds_asked", "…")} --out $OUT`; here
`.venv/bin/python benchmarks/gpu_base.py evaluate --weights {weights} --source {source}{batch_flag}`.
""",
    )


def _same_weights(weights: Path, assembled: Path) -> dict:
    """`weights`' train log; SystemExit if a checkpoint was already assembled (`assembled`, its copy of the
    log) from other weights, since the finished stages would otherwise be reused for them."""
    train_log = json.loads((weights / "train_log.json").read_text())
    if assembled.exists() and json.loads(assembled.read_text()) != train_log:
        raise SystemExit(
            f"{assembled.parent} holds cells of other weights than {weights}: use another --workdir, or "
            "delete that folder's assemble.json and eval_* markers to evaluate these."
        )
    return train_log


def _cpu_profile(eval_batch: int | None) -> dict:
    from lerobot_ocr.pipeline import PUSHT

    p = dict(PUSHT.profiles["cpu"])
    if eval_batch:  # episode i has seed EVAL_SEED + i whatever the batch; larger batches use the CPU better
        p["eval_batch"] = eval_batch
    return p


def continual_pack(work: Path, source: Path, collect_episodes: int | None, eval_batch: int | None) -> None:
    """The gpu row's continual-learning data: its joint policy (in `work`) collects `collect_episodes`
    successful OOD episodes (`benchmarks/continual.py`'s collect stage), merged with `source`'s base data,
    packed into `.gpu/` for `train`. Stages resume, in `work/continual_episode/`."""
    from continual import PROFILES, collect, merge

    from lerobot_ocr.pipeline import PUSHT, Stages

    collect_episodes = collect_episodes or PROFILES["cpu"]["collect"]
    p = {**_cpu_profile(eval_batch), "collect": collect_episodes}
    here = work / "continual_episode"
    stage, logs = Stages(here), here / "logs"
    joint = work / "ocr" / "checkpoints" / "last" / "pretrained_model"
    base_data = source / "base_data"
    for path, how in ((joint, "run `evaluate` first"), (base_data, "pass the chain the gpu base used")):
        if not path.exists():
            raise SystemExit(f"{path} does not exist: {how}.")
    here.mkdir(parents=True, exist_ok=True)
    stage(
        "collect",
        lambda: collect(PUSHT, p, joint, base_data, here / "collected", "episode", logs / "collect.log"),
    )
    stage("merge", lambda: merge(PUSHT, base_data, here / "collected", here / "merged", logs / "merge.log"))

    def pack_merged():
        pack(here / "merged", "local/pusht_aug")
        items = json.loads((PACK / "source.json").read_text())["items"]
        return {"items": items, "source": str(source), "collect": collect_episodes, "eval_batch": eval_batch}

    packed = stage("pack", pack_merged)
    source_json = PACK / "source.json"
    if not source_json.exists() or json.loads(source_json.read_text())["data"] != str(
        (here / "merged").resolve()
    ):
        pack_merged()  # .gpu/ was packed with other data since
    print(
        f"{packed['items']} items in {PACK}: train them on the GPU machine, `train --steps <the gpu base's>`"
    )


def continual_evaluate(weights: Path, work: Path, eval_batch: int | None) -> None:
    """The gpu row's Table III: the base retrained from scratch on the merged data with the same recipe, steps
    and seed as the gpu base (so the gpu base is the control: same training, the demos alone), evaluated
    alone and inside the joint policy (`lerobot-ocr rebase`), ID and OOD; a paired ID check against the gpu
    base. Writes `benchmarks/results/pusht_continual_gpu.json` and RESULTS.md's section."""
    from continual import PAPER, collection_line, paired_line
    from results_md import update_section

    from lerobot_ocr.continual.rebase import rebase
    from lerobot_ocr.eval_report import format_table, paired_outcomes
    from lerobot_ocr.pipeline import EVAL_SEED, PUSHT, Stages, evaluate_cells

    p = _cpu_profile(eval_batch)
    here = work / "continual_episode"
    stage = Stages(here)
    aug = here / "base_aug" / "checkpoints" / "last" / "pretrained_model"
    joint_aug = here / "joint_aug"
    needed = [work / "train_log.json", work / "eval_base_id" / "episodes.json", here / "pack.json"]
    needed += [work / f"eval_{name}.json" for name in ("base_id", "base_ood", "joint_ood", "joint_id")]
    if missing := [str(path) for path in needed if not path.exists()]:
        raise SystemExit(f"Missing {missing}: run `evaluate` (all four cells) and `continual-pack` first.")
    train_log = _same_weights(weights, here / "train_log.json")
    base_log = json.loads((work / "train_log.json").read_text())
    # the inverse policy the gpu row's joint took (`evaluate`'s assemble stage), for the settings
    source_joint = Path(json.loads((work / "assemble.json").read_text())["result"]["inverse_policy_from"])
    if not (source_joint / "train_config.json").exists():
        raise SystemExit(f"{source_joint} (the gpu row's inverse policy) is gone: rebuild its chain first.")
    source_train = json.loads((source_joint / "train_config.json").read_text())
    same = (
        train_log["recipe"] == base_log["recipe"]
        and train_log["steps_planned"] == train_log["steps_done"] == base_log["steps_planned"]
        and base_log["steps_done"] == base_log["steps_planned"]
    )
    if not same:
        raise SystemExit(
            f"{weights} was not trained like the gpu base in {work} (recipe, or steps done / planned "
            f"{train_log['steps_done']}/{train_log['steps_planned']} vs "
            f"{base_log['steps_done']}/{base_log['steps_planned']}): the gpu base would not be its control. "
            f"Train with `train --steps {base_log['steps_planned']}`."
        )

    def assemble():
        assemble_checkpoint(weights, aug, here / "merged", "local/pusht_aug")
        (here / "train_log.json").write_text(json.dumps(train_log, indent=1))
        rebase(work / "ocr" / "checkpoints" / "last" / "pretrained_model", aug, joint_aug, overwrite=True)
        return {"steps": train_log["steps_done"], "items": train_log["items"]}

    stage("assemble", assemble)
    results = {
        name: json.loads((work / f"eval_{name}.json").read_text())["result"]
        for name in ("base_id", "base_ood", "joint_ood", "joint_id")
    }
    cells = {
        "aug_base_ood": (aug, "ood"),
        "aug_base_id": (aug, "id"),
        "aug_joint_ood": (joint_aug, "ood"),
        "aug_joint_id": (joint_aug, "id"),
    }
    results.update(evaluate_cells(stage, PUSHT, cells, p))
    paired = paired_outcomes(
        json.loads((work / "eval_base_id" / "episodes.json").read_text()),
        json.loads((here / "eval_aug_base_id" / "episodes.json").read_text()),
    )
    collection = json.loads((here / "collect.json").read_text())["result"]
    data = json.loads((here / "merge.json").read_text())["result"]
    packed = json.loads((here / "pack.json").read_text())["result"]
    table = format_table(results)
    lines = [
        collection_line("episode", collection, data)
        + f"; `aug_base` trained from scratch with the gpu base's "
        f"recipe, seed and {train_log['steps_done']} steps on the merged data.",
        paired_line(paired),
    ]
    print(table + "\n\n" + "\n".join(lines))
    record = {
        "task": "pusht",
        "profile": "gpu",
        "label": "gpu",
        "keep": "episode",
        "settings": {**row_settings(p, base_log, source_train), "collect": packed["collect"]},
        "recipe": RECIPE,
        "aug_training": {k: train_log[k] for k in ("steps_done", "train_seconds", "gpu", "torch", "items")},
        "date": dt.date.today().isoformat(),
        "machine": f"eval: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}",
        "collection": collection,
        "merged": data,
        "paired_id": paired,
        "cells": results,
        "paper": PAPER["pusht"],
    }
    (HERE / "results" / "pusht_continual_gpu.json").write_text(
        json.dumps(record, indent=2, default=str) + "\n"
    )
    batch_flag = f" --eval-batch {eval_batch}" if eval_batch else ""
    pack_flags = f"--workdir {work} --source {packed['source']} --collect {packed['collect']}"
    pack_flags += f" --eval-batch {packed['eval_batch']}" if packed["eval_batch"] else ""
    update_section(
        "Continual learning (Push-T, gpu)",
        f"""
The gpu row's chain (`{work}`): its joint policy collected the episodes; `aug_base` = a base trained from
scratch on the demos plus those episodes with exactly the gpu base's training (recipe, seed,
{train_log["steps_done"]} steps on one {train_log["gpu"]}), so the gpu base itself is the control (the same
training on the demos alone); `aug_joint` = the joint policy with `aug_base` (`lerobot-ocr rebase`). Paper
(Table III): {PAPER["pusht"]}. {p["episodes"]} episodes per cell, env seeds {EVAL_SEED}+i, evaluated on CPU.

{table}

{chr(10).join(lines)}

Machine: {record["machine"]}. Date: {record["date"]}.

Commands: `.venv/bin/python benchmarks/gpu_base.py continual-pack {pack_flags}`; on the GPU machine
`python3 benchmarks/gpu_base.py train --steps {train_log["steps_done"]} --out $OUT`; here
`.venv/bin/python benchmarks/gpu_base.py continual-evaluate --weights {weights} --workdir {work}{batch_flag}`.
""",
    )
    from summary import write as write_summary

    write_summary()  # the summary's Table III rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    a = sub.add_parser("pack", help="here: items, config and LeRobot's packages -> .gpu/")
    a.add_argument("--workdir", type=Path, default=REPO / "outputs" / "pusht_ocr_cpu")
    b = sub.add_parser("train", help="on the GPU machine")
    b.add_argument("--seconds", type=float, default=420)
    b.add_argument(
        "--steps", type=int, default=None, help="exactly this many steps; --seconds is then ignored"
    )
    b.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", "outputs/gpu_base")))
    c = sub.add_parser("evaluate", help="here: checkpoint, cells, results")
    d = sub.add_parser("continual-pack", help="here: the gpu row's joint policy collects; merge; pack")
    e = sub.add_parser(
        "continual-evaluate", help="here: the base retrained on the merged data, cells, results"
    )
    for sub_parser in (c, e):
        sub_parser.add_argument(
            "--weights", type=Path, required=True, help="the train command's output folder"
        )
    for sub_parser, help_ in (
        (c, "a finished chain: its base_data and inverse policy"),
        (d, "the gpu base's chain"),
    ):
        sub_parser.add_argument("--source", type=Path, default=REPO / "outputs" / "pusht_ocr_cpu", help=help_)
    for sub_parser in (c, d, e):
        sub_parser.add_argument(
            "--workdir", type=Path, default=REPO / "outputs" / "pusht_ocr_gpu", help="the gpu row"
        )
        sub_parser.add_argument(
            "--eval-batch", type=int, default=None, help="envs per batch (default: the cpu profile's)"
        )
    c.add_argument("--cells", nargs="*", default=["base_id", "joint_ood", "base_ood", "joint_id"])
    d.add_argument(
        "--collect", type=int, default=None, help="successful episodes (default: continual.py's cpu)"
    )
    args = parser.parse_args()
    if args.command == "pack":
        pack(args.workdir / "base_data")
    elif args.command == "continual-pack":
        continual_pack(args.workdir, args.source, args.collect, args.eval_batch)
    elif args.command == "continual-evaluate":
        continual_evaluate(args.weights, args.workdir, args.eval_batch)
    elif args.command == "train":
        args.out.mkdir(parents=True, exist_ok=True)
        train(PACK if (PACK / "items.pt").exists() else Path(".gpu"), args.seconds, args.out, args.steps)
    else:
        evaluate(args.weights, args.source, args.workdir, args.cells, args.eval_batch)


if __name__ == "__main__":
    main()
