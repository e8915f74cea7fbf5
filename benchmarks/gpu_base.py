"""The `gpu` rows: low-dim networks trained with Diffusion Policy's own low-dim recipe on a GPU for a few
minutes, then evaluated here on CPU beside the `cpu` rows (same data, seeds and protocol). Push-T trains
its base there (the inverse policy is the `cpu` chain's); Square trains both its base and its inverse
policy there, in two processes side by side.

    .venv/bin/python benchmarks/gpu_base.py pack                       # here: items + packages -> .gpu/
    python3 benchmarks/gpu_base.py train --seconds 420 --out "$OUT"    # on the GPU machine (bare torch)
    .venv/bin/python benchmarks/gpu_base.py evaluate --weights <dir>   # here: checkpoint, 4 cells, JSON

    .venv/bin/python benchmarks/gpu_base.py pack --task square         # here: demos, both packs -> .gpu/
    python3 benchmarks/gpu_base.py train --part base --seconds 380 --out "$OUT/base" &   # GPU machine
    python3 benchmarks/gpu_base.py train --part inverse --seconds 380 --out "$OUT/inverse" & wait
    .venv/bin/python benchmarks/gpu_base.py evaluate --task square --weights <dir>   # here: 4 cells

and the paper's Table III on the Push-T row (after `evaluate`):

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
which `pack` copies into `.gpu/site.tar.gz` (the GPU image has torch, numpy, huggingface_hub; no LeRobot).
`evaluate` wraps the new base with the inverse policy of a finished `cpu`-profile chain (`lerobot-ocr
rebase`) and runs the four cells of `benchmarks/pusht_ocr.py` (resumable), writing
`benchmarks/results/pusht_gpu.json` and RESULTS.md's "Push-T (gpu)" section. `continual-pack` has the
row's joint policy collect OOD episodes (`benchmarks/continual.py`'s stage), merges them with the demos and
packs the merged data into `.gpu/` (replacing the base's pack); `continual-evaluate` checks that the weights
were trained exactly like the gpu base but on that pack, so the gpu base is the control.

Square (`--task square`): `pack` runs the `cpu` chain's data stages (`pipeline.chain_data`: demos, base
data, convert; resumable, shared with `benchmarks/square_ocr.py`), packs the base's items, and builds an
ocr_joint checkpoint by the shipped training command with one step (`pipeline.ocr_train_args`): its
manifold, threshold and the inverse policy's normalisation are fitted here exactly as a full training run
fits them, and `.gpu/inverse.pt` holds that normalisation with the training table (keypoints, state,
frames, actions per frame). `train --part inverse` trains `KeypointInversePolicy.compute_loss` on windows
cut from that table (every frame a window start, as lerobot-train samples ocr_joint) with the same recipe;
`evaluate --task square` puts its EMA weights into that checkpoint (refusing other normalisation), rebases
it onto the gpu base and runs the Square cells, writing `square_gpu.json` and "Square (gpu)".
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
# results_md, continual and lerobot_ocr, imported lazily (the GPU machine needs only lerobot_ocr's
# inverse_policy and dataset_columns, for `train --part inverse`: torch, numpy and pandas are there)
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
# Square's inverse policy, trained beside its base with the same recipe: both fp16 weight sets must fit the
# 64 MiB that come back (base 31.8 MiB + inverse 26.0 MiB at (112, 224, 448); at (128, 256, 512) 33.3 MiB).
INVERSE_DOWN_DIMS = (112, 224, 448)
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
    own statistics), `out/config/config.json` and `out/site.tar.gz`."""
    shutil.rmtree(out, ignore_errors=True)
    pack_base(data, repo_id, out)
    pack_site(out)


def pack_base(data: Path, repo_id: str, out: Path) -> None:
    """The base's training items (`out/items.pt`), config (`out/config/`) and their source (`source.json`)."""
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
    (out / "config").mkdir(parents=True)
    torch.save(batch, out / "items.pt")
    cfg.save_pretrained(out / "config")
    (out / "source.json").write_text(json.dumps({"data": str(data.resolve()), "items": len(indices)}))
    print(f"packed {len(indices)} base items, keys {sorted(batch)}")


def pack_site(out: Path) -> None:
    """LeRobot's pure-Python packages that the GPU image lacks, as `out/site.tar.gz` (a fifth of their size,
    so a pack fits the 64 MiB that travel; `train` unpacks it)."""
    import tarfile

    site = Path(next(p for p in sys.path if p.endswith("site-packages")))
    sources = [src for name in PACKAGES for src in [site / name, *site.glob(f"{name}-*.dist-info")]]
    sources += list(site.glob("av-*.dist-info"))  # its metadata only: LeRobot checks av's version at import
    sources += [site / py for py in ("mergedeep.py",)]
    with tarfile.open(out / "site.tar.gz", "w:gz") as tar:
        for src in sources:
            if src.exists():
                tar.add(src, arcname=f"site/{src.name}", filter=_no_bytecode)
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    print(f"{size / 2**20:.1f} MiB in {out}")


def _no_bytecode(info):
    return None if "__pycache__" in info.name or info.name.endswith(".pyc") else info


def inverse_pack(policy) -> dict:
    """What `train --part inverse` needs of an ocr_joint `policy` built with its training table
    (lerobot-train's `make_policy(cfg, ds_meta=…)`, or `_load_training_table`): the network's arguments,
    its fitted normalisation buffers and the table (world keypoints (N, K, D), robot state (N, S),
    object frames (N, D+1, D+1), actions (N, A), each frame's episode end (N,))."""
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import inverse_policy_kwargs

    k, d = policy.object_keypoints_.shape
    kwargs = inverse_policy_kwargs(
        policy.config, k, d, policy._tbl_state.shape[-1], policy._tbl_action.shape[-1]
    )
    return {
        "kwargs": kwargs,
        "fitted": {k: v for k, v in policy.inverse.state_dict().items() if not k.startswith("diffusion.")},
        "table": {
            "keypoints": policy._tbl_keypoints,
            "state": policy._tbl_state,
            "frames": policy._tbl_frames,
            "action": policy._tbl_action,
            "last": policy._tbl_last,
        },
    }


def pack_square(source: Path, work: Path, out: Path = PACK) -> None:
    """Square's pack: the `cpu` chain's data stages in `source` (resumable), the base's items, an ocr_joint
    checkpoint trained one step by the shipped command in `work/placeholder` (manifold, threshold and the
    inverse policy's normalisation fitted as in a full run; its base: an untrained network of the recipe's
    shape, replaced at `evaluate`), and `out/inverse.pt`: that normalisation, the network's arguments
    (`inverse_policy_kwargs`) and the training table."""
    import torch

    from lerobot_ocr.pipeline import SQUARE, chain_data, ocr_train_args, run
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    p = SQUARE.profiles["cpu"]
    data = chain_data(SQUARE, p, source)
    shutil.rmtree(out, ignore_errors=True)
    pack_base(data.base_data, data.base_repo, out)
    placeholder = work / "placeholder"
    shutil.rmtree(placeholder, ignore_errors=True)
    base = placeholder / "base"
    save_base_checkpoint(None, base, data.base_data, data.base_repo)
    one_step = {**p, "ocr_steps": 1, "ocr_dims": str(list(INVERSE_DOWN_DIMS)), "ocr_batch": RECIPE["batch"]}
    run(ocr_train_args(SQUARE, one_step, data, base, placeholder / "ocr"), work / "logs" / "placeholder.log")
    joint = placeholder / "ocr" / "checkpoints" / "last" / "pretrained_model"
    policy = OcrJointPolicy.from_pretrained(joint)
    policy._load_training_table(data.converted)
    torch.save({**inverse_pack(policy), "joint": str(joint.resolve())}, out / "inverse.pt")
    source_json = json.loads((out / "source.json").read_text())
    source_json["inverse"] = {"data": str(data.converted.resolve()), "windows": len(policy._tbl_index)}
    (out / "source.json").write_text(json.dumps(source_json))
    print(f"packed {len(policy._tbl_index)} inverse-policy windows (U-Net {list(INVERSE_DOWN_DIMS)})")
    pack_site(out)


def _import_lerobot(pack_dir: Path) -> None:
    """Make LeRobot importable on the GPU image: our copies (`pack_dir/site`, unpacked from `site.tar.gz`
    once, atomically, as two `train` processes may start together) after its own packages; PyAV stubbed
    (only video decoding needs it, and this script decodes no video); `lerobot_ocr` as a bare namespace, so
    its modules import without the package's `__init__` (which registers envs and robots)."""
    import importlib.machinery
    import tarfile
    import tempfile
    import types

    site = pack_dir / "site"
    if not site.is_dir() and (pack_dir / "site.tar.gz").is_file():
        staging = Path(tempfile.mkdtemp(dir=pack_dir))
        with tarfile.open(pack_dir / "site.tar.gz") as tar:
            tar.extractall(staging, filter="data")
        try:
            (staging / "site").rename(site)
        except OSError:  # the other process was first
            pass
        shutil.rmtree(staging, ignore_errors=True)
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
    if "lerobot_ocr" not in sys.modules:
        package = types.ModuleType("lerobot_ocr")
        package.__path__ = [str(REPO / "src" / "lerobot_ocr")]
        sys.modules["lerobot_ocr"] = package


def _base_part(pack_dir: Path, device: str):
    """The base: (items, build, loss, save_config) for `train`."""
    import torch
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy

    cfg = PreTrainedConfig.from_pretrained(pack_dir / "config")
    cfg.device = device
    data = {k: v.to(device) for k, v in torch.load(pack_dir / "items.pt").items()}

    def loss(policy, idx):
        return policy.forward({k: v[idx] for k, v in data.items()})[0]

    n = len(next(iter(data.values())))
    return n, lambda: DiffusionPolicy(cfg).to(device).train(), loss, cfg.save_pretrained


def _inverse_part(pack_dir: Path, device: str):
    """Square's inverse policy: (windows, build, loss, save_config) for `train`; each window starts at a
    frame of the packed table, the loss is `KeypointInversePolicy.compute_loss`, as in lerobot-train."""
    import torch

    from lerobot_ocr.dataset_columns import window_positions
    from lerobot_ocr.inverse_policy import KeypointInversePolicy

    if not (pack_dir / "inverse.pt").is_file():
        raise SystemExit(f"{pack_dir} holds no inverse.pt: make the pack with `pack --task square`.")
    packed = torch.load(pack_dir / "inverse.pt")
    table = {k: v.to(device) for k, v in packed["table"].items()}
    horizon = packed["kwargs"]["horizon"]

    def build():
        model = KeypointInversePolicy(**packed["kwargs"])
        missing, unexpected = model.load_state_dict(packed["fitted"], strict=False)
        if unexpected or any(not k.startswith("diffusion.") for k in missing):
            raise RuntimeError(
                f"inverse.pt does not fit the network: missing {missing}, unexpected {unexpected}"
            )
        return model.to(device).train()

    def loss(model, idx):
        win, is_pad = window_positions(idx, table["last"][idx], horizon)
        return model.compute_loss(
            table["keypoints"][win], table["state"][idx], table["frames"][idx], table["action"][win], is_pad
        )

    return len(table["last"]), build, loss, lambda out: None  # its arguments go into train_log.json


def train(
    pack_dir: Path,
    seconds: float,
    out: Path,
    steps: int | None = None,
    part: str = "base",
    seed: int | None = None,
) -> None:
    """Train the base (`part` "base") or Square's inverse policy ("inverse") for about `seconds` on the GPU
    (or exactly `steps` steps); write to `out` the base's config.json, the EMA weights as fp16 shards
    `ema_fp16_<i>.safetensors` (refreshed every minute, so a cut run still returns them) and train_log.json
    (with the inverse policy's arguments): 5 files for the base, 3 for the inverse policy (its 26 MiB in
    two 15 MiB shards), 8 together, what the GPU machine returns. `seed` (default
    the recipe's) seeds the initial weights, the noise and the batch order."""
    seed = RECIPE["seed"] if seed is None else seed
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    _import_lerobot(pack_dir)
    import torch
    from diffusers.optimization import get_cosine_schedule_with_warmup
    from torch.optim.swa_utils import AveragedModel

    torch.backends.cuda.matmul.allow_tf32 = True
    torch.backends.cudnn.allow_tf32 = True
    device = "cuda" if torch.cuda.is_available() else "cpu"  # cpu: a smoke test of this script only
    sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
    n, make_model, loss_fn, save_config = (_base_part if part == "base" else _inverse_part)(pack_dir, device)
    pack_source = json.loads((pack_dir / "source.json").read_text())
    extra = {}  # for train_log.json
    if part == "inverse":
        pack_source = pack_source["inverse"]
        extra["inverse_kwargs"] = torch.load(pack_dir / "inverse.pt")["kwargs"]
    batch_size = RECIPE["batch"]

    def ema_update(averaged, current, num_averaged):  # Diffusion Policy's EMA warm-up (power 0.75)
        step = int(num_averaged)
        decay = min(RECIPE["ema_max"], max(0.0, 1 - (1 + step) ** -RECIPE["ema_power"]))
        if averaged[0].is_floating_point():  # AveragedModel calls this once per device and dtype
            torch._foreach_lerp_(averaged, current, 1 - decay)
        else:  # flags (the inverse policy's `fitted_`) are copied
            torch._foreach_copy_(averaged, current)

    def build():
        torch.manual_seed(seed)
        policy = make_model()
        optimizer = torch.optim.AdamW(
            policy.parameters(),
            lr=RECIPE["lr"],
            betas=RECIPE["betas"],
            eps=1e-8,
            weight_decay=RECIPE["weight_decay"],
        )
        return policy, optimizer

    def step_fn(policy, optimizer, idx):
        loss = loss_fn(policy, idx)
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
    gen = torch.Generator(device=device).manual_seed(seed)
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
        save_config(out)
        info = {
            "part": part,
            "recipe": RECIPE,
            "seed": seed,
            **extra,
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
    from lerobot.policies.diffusion import configuration_diffusion  # noqa: F401  (registers "diffusion")

    cfg = PreTrainedConfig.from_pretrained(weights)
    check_trained_on(json.loads((weights / "train_log.json").read_text()), data, cfg)
    save_base_checkpoint(load_shards(weights), out, data, repo_id, cfg)


def load_shards(weights: Path) -> dict:
    """The fp16 EMA shards `weights/ema_fp16_<i>.safetensors` as one fp32 state dict."""
    from safetensors.torch import load_file

    state = {}
    for shard in sorted(weights.glob("ema_fp16_*.safetensors")):
        state.update(load_file(shard))
    if not state:
        raise SystemExit(f"{weights} holds no ema_fp16_*.safetensors: pass the train command's --out folder.")
    return {k: v.float() if v.is_floating_point() else v for k, v in state.items()}


def save_base_checkpoint(state: dict | None, out: Path, data: Path, repo_id: str, cfg=None) -> None:
    """A LeRobot `DiffusionPolicy` checkpoint in `out`: config `cfg` (default: `base_config` of the dataset
    at `data`), weights `state` (None: untrained, seeded), processors from `data`'s statistics."""
    import torch
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from lerobot.policies.factory import make_pre_post_processors

    meta = LeRobotDatasetMetadata(repo_id, root=data)
    cfg = cfg or base_config(meta)
    cfg.device = "cpu"
    torch.manual_seed(RECIPE["seed"])
    policy = DiffusionPolicy(cfg)
    if state is not None:
        policy.load_state_dict(state)
    shutil.rmtree(out, ignore_errors=True)
    policy.save_pretrained(out)
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

    from lerobot_ocr.pipeline import BIN, PUSHT, Stages, run
    from lerobot_ocr.splits import DEV

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

    results, table = _assembled_cells(stage, assemble, PUSHT, base, joint, cells, p)
    if results is None:
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
per cell, env seeds {DEV.start}+i, evaluated on CPU; {PUSHT.episode_length}-step episodes, success within
{PUSHT.step_budget} steps (strict) and within {PUSHT.decision_budget} policy decisions.

{table}

Machine: {payload["machine"]}. Date: {payload["date"]}.

Commands: `.venv/bin/python benchmarks/gpu_base.py pack --workdir {source}`; on the GPU machine
`python3 benchmarks/gpu_base.py train --seconds {train_log.get("seconds_asked", "…")} --out $OUT`; here
`.venv/bin/python benchmarks/gpu_base.py evaluate --weights {weights} --source {source}{batch_flag}`.
""",
    )


def assemble_joint(inverse_weights: Path, placeholder: Path, base: Path, out: Path) -> None:
    """The Square gpu row's ocr_joint checkpoint in `out`: the `pack --task square` checkpoint `placeholder`
    (its manifold, threshold and fp32 normalisation) with the inverse network's EMA weights from
    `inverse_weights` (the train command's `--part inverse` folder), rebased onto `base`.

    Raises:
        SystemExit: the weights were trained with another normalisation or network than `placeholder`
            holds (a stale pack, or another chain's).
    """
    import tempfile

    import torch

    from lerobot_ocr.continual.rebase import rebase
    from lerobot_ocr.policies.ocr_joint.modeling_ocr_joint import OcrJointPolicy

    policy = OcrJointPolicy.from_pretrained(placeholder)
    state = load_shards(inverse_weights)
    own = policy.inverse.state_dict()
    fitted = [k for k in own if not k.startswith("diffusion.")]
    stale = [
        k
        for k in fitted
        if k not in state
        or not torch.equal(
            own[k].to(torch.float16).float() if own[k].is_floating_point() else own[k], state[k]
        )
    ]
    shapes = {k: tuple(v.shape) for k, v in own.items()} == {k: tuple(v.shape) for k, v in state.items()}
    if stale or not shapes:
        raise SystemExit(
            f"{inverse_weights} was not trained on the normalisation of {placeholder} "
            f"({stale or 'another network'}): run `pack --task square` and train again, or pass the pack's "
            "--workdir."
        )
    policy.inverse.load_state_dict({**state, **{k: own[k] for k in fitted}})  # fp32 statistics kept
    with tempfile.TemporaryDirectory(dir=out.parent if out.parent.exists() else None) as tmp:
        policy.save_pretrained(Path(tmp) / "joint")
        rebase(Path(tmp) / "joint", base, out, overwrite=True)


def evaluate_square(
    weights: Path, source: Path, work: Path, cells: list[str], eval_batch: int | None = None
) -> None:
    """The Square gpu row: the base (`weights/base`) and the inverse policy (`weights/inverse`) trained on
    the GPU, assembled in `work` (`assemble_checkpoint`, `assemble_joint`) and evaluated with the `cpu` row's
    protocol (the Square task's budgets, 100 episodes per cell, seeds 100000+i; resumable); writes
    `benchmarks/results/square_gpu.json` and RESULTS.md's "Square (gpu)" section once all four cells exist."""
    from ocr_pipeline import diagnosis, diagnosis_text
    from results_md import update_section
    from summary import write as write_summary

    from lerobot_ocr.pipeline import SQUARE, Chain, Stages
    from lerobot_ocr.splits import DEV

    p = dict(SQUARE.profiles["cpu"])
    if eval_batch:  # episode i has seed DEV.start + i whatever the batch
        p["eval_batch"] = eval_batch
    stage = Stages(work)
    base = work / "base" / "checkpoints" / "last" / "pretrained_model"
    joint = work / "ocr" / "checkpoints" / "last" / "pretrained_model"
    placeholder = work / "placeholder" / "ocr" / "checkpoints" / "last" / "pretrained_model"
    if not placeholder.is_dir():
        raise SystemExit(f"{placeholder} is missing: run `pack --task square --workdir {work}` first.")
    logs = {
        part: _same_weights(weights / part, work / f"train_log_{part}.json") for part in ("base", "inverse")
    }

    def assemble():
        assemble_checkpoint(weights / "base", base, source / "base_data", "local/square_base")
        joint.parent.mkdir(parents=True, exist_ok=True)
        assemble_joint(weights / "inverse", placeholder, base, joint)
        for part, log in logs.items():
            (work / f"train_log_{part}.json").write_text(json.dumps(log, indent=1))
        return {part: log["steps_done"] for part, log in logs.items()}

    results, table = _assembled_cells(stage, assemble, SQUARE, base, joint, cells, p)
    if results is None:
        return  # the row is published once all four cells exist
    eval_dirs = {name: work / f"eval_{name}" for name in results}
    d = diagnosis(Chain(results, eval_dirs, base, joint, source / "converted", stage.times))
    kwargs = logs["inverse"]["inverse_kwargs"]
    settings = {
        **p,
        "base_dims": str(list(RECIPE["down_dims"])),
        "base_steps": logs["base"]["steps_done"],
        "base_batch": RECIPE["batch"],
        "ocr_dims": str(list(kwargs["down_dims"])),
        "ocr_steps": logs["inverse"]["steps_done"],
        "ocr_batch": RECIPE["batch"],
    }
    payload = {
        "benchmark": "square_ocr",
        "profile": "gpu",
        "settings": settings,
        "recipe": RECIPE,
        "training": {
            part: {k: log[k] for k in ("steps_done", "train_seconds", "gpu", "torch", "items")}
            for part, log in logs.items()
        },
        **results,
        "handback_diagnosis": d,
        "stage_seconds": stage.times,
        "machine": f"eval: {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}",
        "date": dt.date.today().isoformat(),
    }
    (HERE / "results" / "square_gpu.json").write_text(json.dumps(payload, indent=2) + "\n")
    write_summary()
    gpu = logs["base"]["gpu"]
    minutes = max(log["train_seconds"] for log in logs.values()) / 60
    batch_flag = f" --eval-batch {eval_batch}" if eval_batch else ""
    seconds = logs["base"].get("seconds_asked") or "…"
    rel = {
        k: os.path.relpath(v, REPO) for k, v in {"source": source, "work": work, "weights": weights}.items()
    }
    update_section(
        "Square (gpu)",
        f"""
The `cpu` row's {p["demos"]} scripted ID demos and low-dim features; both networks trained with Diffusion
Policy's low-dim recipe on one {gpu}, side by side in {minutes:.1f} min (batch {RECIPE["batch"]}, AdamW
1e-4, cosine with 500 warm-up steps, EMA weights of power 0.75, seed {logs["base"].get("seed", 1000)}):
the base U-Net {list(RECIPE["down_dims"])}, {logs["base"]["steps_done"]} steps; the inverse policy U-Net
{list(kwargs["down_dims"])}, {logs["inverse"]["steps_done"]} steps (`configs/policy/ocr_joint_square.json`
otherwise). {p["episodes"]} episodes per cell, env seeds {DEV.start}+i, evaluated on CPU;
{SQUARE.episode_length}-step episodes ({SQUARE.joint_episode_length} for ocr_joint), success within
{SQUARE.step_budget} steps (strict) and within {SQUARE.decision_budget} calls of the reference's joint budget
in env time (a recovery decision counts its steps / {SQUARE.recovery_call_steps}).
{SQUARE.paper}

{table}

{diagnosis_text(d).strip()}

Machine: {payload["machine"]}. Date: {payload["date"]}.

Commands: `.venv/bin/python benchmarks/gpu_base.py pack --task square --source {rel["source"]} --workdir
{rel["work"]}`; on the GPU machine `python3 benchmarks/gpu_base.py train --part base --seconds {seconds}
--out $OUT/base` beside `... train --part inverse --seconds {seconds} --out $OUT/inverse`; here
`.venv/bin/python benchmarks/gpu_base.py evaluate --task square --weights {rel["weights"]} --source
{rel["source"]} --workdir {rel["work"]}{batch_flag}`.
""",
    )


def _assembled_cells(stage, assemble, task, base: Path, joint: Path, cells: list[str], p: dict):
    """The `assemble` stage, then the cells (resumable), their table printed; (results, table), or
    (None, table) until all four cells exist."""
    from lerobot_ocr.eval_report import format_table
    from lerobot_ocr.pipeline import CELLS, chain_cells, evaluate_cells

    stage("assemble", assemble)
    results = evaluate_cells(stage, task, chain_cells(base, joint, cells), p)
    table = format_table(results)
    print("\n" + table)
    return (results if set(results) == set(CELLS) else None), table


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
    if eval_batch:  # episode i has seed DEV.start + i whatever the batch; larger batches use the CPU better
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
    from lerobot_ocr.pipeline import PUSHT, Stages, evaluate_cells
    from lerobot_ocr.splits import DEV

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
(Table III): {PAPER["pusht"]}. {p["episodes"]} episodes per cell, env seeds {DEV.start}+i, evaluated on CPU.

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
    b = sub.add_parser("train", help="on the GPU machine")
    b.add_argument("--seconds", type=float, default=420)
    b.add_argument(
        "--steps", type=int, default=None, help="exactly this many steps; --seconds is then ignored"
    )
    b.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", "outputs/gpu_base")))
    b.add_argument("--seed", type=int, default=None, help="default: the recipe's")
    b.add_argument("--part", choices=("base", "inverse"), default="base", help="inverse: Square's pack only")
    c = sub.add_parser("evaluate", help="here: checkpoint, cells, results")
    d = sub.add_parser("continual-pack", help="here: the gpu row's joint policy collects; merge; pack")
    e = sub.add_parser(
        "continual-evaluate", help="here: the base retrained on the merged data, cells, results"
    )
    for sub_parser in (c, e):
        sub_parser.add_argument(
            "--weights", type=Path, required=True, help="the train command's output folder"
        )
    for sub_parser in (a, c):
        sub_parser.add_argument("--task", choices=("pusht", "square"), default="pusht")
    for sub_parser, help_ in (
        (a, "square: the cpu chain whose data stages run here (Push-T packs --workdir's base_data)"),
        (c, "a finished chain: its base_data and inverse policy (square: its data)"),
        (d, "the gpu base's chain"),
    ):
        sub_parser.add_argument("--source", type=Path, default=None, help=help_)
    for sub_parser in (a, c, d, e):
        sub_parser.add_argument(
            "--workdir", type=Path, default=None, help="the gpu row (Push-T `pack`: the cpu chain it packs)"
        )
    for sub_parser in (c, d, e):
        sub_parser.add_argument(
            "--eval-batch", type=int, default=None, help="envs per batch (default: the cpu profile's)"
        )
    c.add_argument("--cells", nargs="*", default=["base_id", "joint_ood", "base_ood", "joint_id"])
    d.add_argument(
        "--collect", type=int, default=None, help="successful episodes (default: continual.py's cpu)"
    )
    args = parser.parse_args()
    task = getattr(args, "task", "pusht")
    source = getattr(args, "source", None) or REPO / "outputs" / f"{task}_ocr_cpu"
    workdir = getattr(args, "workdir", None) or REPO / "outputs" / f"{task}_ocr_gpu"
    if args.command == "pack" and task == "square":
        pack_square(source, workdir)
    elif args.command == "pack":  # Push-T: the base's items only (--workdir: the cpu chain, as before)
        pack((args.workdir or REPO / "outputs" / "pusht_ocr_cpu") / "base_data")
    elif args.command == "continual-pack":
        continual_pack(workdir, source, args.collect, args.eval_batch)
    elif args.command == "continual-evaluate":
        continual_evaluate(args.weights, workdir, args.eval_batch)
    elif args.command == "train":
        pack_dir = PACK if (PACK / "source.json").exists() else Path(".gpu")
        train(pack_dir, args.seconds, args.out, args.steps, args.part, args.seed)
    elif task == "square":
        evaluate_square(args.weights, source, workdir, args.cells, args.eval_batch)
    else:
        evaluate(args.weights, source, workdir, args.cells, args.eval_batch)


if __name__ == "__main__":
    main()
