"""One expert rollout loop for every task (benchmarks, tests and the dataset generators use it)."""

from __future__ import annotations

from collections.abc import Callable


def rollout(
    env, expert, seed: int, max_steps: int, record: Callable[[dict, object], dict] | None = None
) -> dict:
    """Roll `expert` out on a (wrapped) env from `seed` until success, truncation or `max_steps`.

    The expert is reset after the env (`expert.reset(unwrapped_env)`) and asked for each action with
    `expert.act(unwrapped_env)`. `record(obs, unwrapped_env)` picks what each step keeps of the
    observation it acted on (default: {"obs": obs}); every step also keeps action, reward, success.
    Returns {"steps", "success", "length", "start_region"}.
    """
    obs, info = env.reset(seed=seed)
    region = info.get("start_region")
    base = env.unwrapped
    expert.reset(base)
    steps, success = [], False
    for _ in range(max_steps):
        action = expert.act(base)
        kept = record(obs, base) if record is not None else {"obs": obs}
        obs, reward, terminated, truncated, info = env.step(action)
        steps.append({**kept, "action": action, "reward": reward, "success": bool(info["is_success"])})
        if info["is_success"]:
            success = True
            break
        if truncated:
            break
    return {"steps": steps, "success": success, "length": len(steps), "start_region": region}
