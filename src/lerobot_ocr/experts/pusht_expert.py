"""Scripted Push-T expert: a sampling planner over push primitives, simulated in a model of the scene.

Each decision samples contact points along the T's outline (object frame, with the inward face
normal), simulates pushing there in a private copy of the physics (a second gym-pusht env whose
bodies are set to the real state; the env's own `space.copy()` cannot pickle its collision
callback), and picks, among near-best candidates, the push with the largest error reduction per
env step. The agent reaches the pre-contact point along a path that stays clear of the T (straight
if free, else around a circle and in along the face normal), then pushes at a speed that slows
near the goal. Actions are absolute agent targets (pixels), as in gym-pusht.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gym_pusht.envs.pusht import PushTEnv
from pymunk.vec2d import Vec2d

from lerobot_ocr.constants import PUSHT_GOAL_POSE
from lerobot_ocr.envs.pusht_env import block_keypoints
from lerobot_ocr.experts.rollout import rollout

AGENT_RADIUS = 15.0
COM_LOCAL = np.array([0.0, 45.0])
# T boxes in the object frame: (xmin, xmax, ymin, ymax)
_BOXES = np.array([[-60.0, 60.0, 0.0, 30.0], [-15.0, 15.0, 30.0, 120.0]])
# Outline edges with inward normals (object frame): (start, end, inward normal)
_EDGES = [
    ((-60, 0), (60, 0), (0, 1)),  # crossbar underside (y = 0), push +y
    ((-60, 30), (-15, 30), (0, -1)),  # crossbar top left
    ((15, 30), (60, 30), (0, -1)),  # crossbar top right
    ((-60, 0), (-60, 30), (1, 0)),  # crossbar left end
    ((60, 0), (60, 30), (-1, 0)),  # crossbar right end
    ((-15, 30), (-15, 120), (1, 0)),  # stem left side
    ((15, 30), (15, 120), (-1, 0)),  # stem right side
    ((-15, 120), (15, 120), (0, -1)),  # stem end
]


def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def pose_error(block_pose: np.ndarray) -> float:
    """Mean distance (px) between the T's keypoints at `block_pose` and at the goal."""
    return float(
        np.linalg.norm(block_keypoints(block_pose) - block_keypoints(PUSHT_GOAL_POSE), axis=-1).mean()
    )


def distance_to_t(block_pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 2) world points -> (N,) distance to the T (0 inside)."""
    local = (np.asarray(points) - block_pose[:2]) @ _rot(block_pose[2])  # R^T (p - t)
    dx = np.maximum(np.maximum(_BOXES[:, 0] - local[:, None, 0], 0.0), local[:, None, 0] - _BOXES[:, 1])
    dy = np.maximum(np.maximum(_BOXES[:, 2] - local[:, None, 1], 0.0), local[:, None, 1] - _BOXES[:, 3])
    return np.hypot(dx, dy).min(axis=1)


def _contacts(spacing: float) -> tuple[np.ndarray, np.ndarray]:
    pts, normals = [], []
    for a, b, n in _EDGES:
        a, b = np.array(a, float), np.array(b, float)
        length = np.linalg.norm(b - a)
        for s in np.arange(spacing / 2, length - 1e-6, spacing):
            pts.append(a + (b - a) * s / length)
            normals.append(n)
    return np.array(pts), np.array(normals, float)


def _segment_clear(block_pose: np.ndarray, a: np.ndarray, b: np.ndarray, clearance: float) -> bool:
    n = max(2, int(np.linalg.norm(b - a) / 4.0))
    pts = a + np.linspace(0, 1, n)[:, None] * (b - a)
    return bool(distance_to_t(block_pose, pts).min() > clearance)


@dataclass
class PushTExpertConfig:
    contact_spacing: float = 10.0
    gap: float = 6.0  # pre-contact clearance between agent disc and face (px)
    max_depth: float = 150.0  # longest push simulated (px past contact)
    move_speed: float = 16.0  # px per step while moving freely
    clearance: float = AGENT_RADIUS + 4.0
    top_k: int = 3  # random choice among near-best pushes
    pause_prob: float = 0.15  # chance of a short human-like pause between pushes


class PushTExpert:
    """Plans and executes pushes on a `PushTEnv` (or PushTOcrEnv) until success.

    Usage: expert = PushTExpert(seed); then each step `action = expert.act(env)` with the
    unwrapped env (it reads the true state) and `env.step(action)`.
    """

    def __init__(self, seed: int = 0, config: PushTExpertConfig | None = None):
        self.cfg = config or PushTExpertConfig()
        self.rng = np.random.default_rng(seed)
        self.model = PushTEnv(obs_type="state", render_mode="rgb_array")
        self.model.reset(seed=0)
        self.contacts, self.normals = _contacts(self.cfg.contact_spacing)
        self.plan: list[np.ndarray] = []

    def reset(self, env: PushTEnv | None = None) -> None:
        """Forget the current plan (call after each env reset; `env` is unused, for the common rollout)."""
        self.plan = []

    # ----------------------------------------------------------------------- physics model
    def _sync(self, env: PushTEnv, agent_pos: np.ndarray | None = None) -> None:
        m = self.model
        m.block.angle = env.block.angle
        m.block.position = env.block.position
        m.block.velocity = env.block.velocity
        m.block.angular_velocity = env.block.angular_velocity
        if agent_pos is None:
            m.agent.position = env.agent.position
            m.agent.velocity = env.agent.velocity
        else:
            m.agent.position = Vec2d(*agent_pos)
            m.agent.velocity = Vec2d(0, 0)

    def _model_step(self, action: np.ndarray) -> None:
        m = self.model
        n = int(1 / (m.dt * m.control_hz))
        target = Vec2d(*action)
        for _ in range(n):
            acc = m.k_p * (target - m.agent.position) + m.k_v * (Vec2d(0, 0) - m.agent.velocity)
            m.agent.velocity += acc * m.dt
            m.space.step(m.dt)

    def _block_pose(self, env: PushTEnv) -> np.ndarray:
        return np.array([*env.block.position, env.block.angle])

    # ---------------------------------------------------------------------------- planning
    def _push_targets(
        self, start: np.ndarray, normal: np.ndarray, length: float, speed: float
    ) -> list[np.ndarray]:
        n = max(1, int(np.ceil(length / speed)))
        return [start + normal * length * (i + 1) / n for i in range(n)] + [start + normal * length] * 2

    def _plan_push(self, env: PushTEnv) -> list[np.ndarray]:
        cfg = self.cfg
        pose = self._block_pose(env)
        err0 = pose_error(pose)
        speed = float(np.clip(err0 / 4.0, 2.5, 14.0))
        rot = _rot(pose[2])
        agent = np.array(env.agent.position)
        candidates = []
        for c_local, n_local in zip(self.contacts, self.normals):
            c = pose[:2] + rot @ c_local
            n = rot @ n_local
            pre = c - n * (AGENT_RADIUS + cfg.gap)
            if not (20 <= pre[0] <= 492 and 20 <= pre[1] <= 492):
                continue
            if distance_to_t(pose, pre[None])[0] < AGENT_RADIUS + cfg.gap - 1.0:
                continue  # the agent disc does not fit there (e.g. deep in a pocket corner)
            depth = min(cfg.max_depth, 1.5 * err0 + 5.0)
            targets = self._push_targets(pre, n, cfg.gap + depth, speed)
            self._sync(env, agent_pos=pre)
            best = (np.inf, 0)
            for i, t in enumerate(targets):
                self._model_step(t)
                e = pose_error(self._block_pose(self.model))
                if e < 8.0 and self.model._get_coverage() > self.model.success_threshold:
                    best = (0.0, i)  # the rollout predicts success: take the shortcut
                    break
                if e < best[0]:
                    best = (e, i)
            e_best, i_best = best
            if e_best >= err0 - 0.05:
                continue
            approach = np.linalg.norm(pre - agent) / cfg.move_speed + 2
            rate = (err0 - e_best) / (approach + i_best + 1)
            candidates.append((rate, pre, n, targets[: i_best + 1], err0 - e_best))
        if not candidates:
            return []
        candidates.sort(key=lambda x: -x[0])
        # Re-rank the best few with the real approach path (it may go around the T).
        rescored = []
        for _, pre, _, push, gain in candidates[:8]:
            path = self._path_to(pose, agent, pre)
            rescored.append((gain / (len(path) + len(push)), path, push))
        rescored.sort(key=lambda x: -x[0])
        near = [c for c in rescored[: cfg.top_k] if c[0] >= 0.8 * rescored[0][0]]
        _, path, push = near[self.rng.integers(len(near))]
        end = push[-1]
        return path + push + [end, end]  # hold at the end until the agent catches up

    def _path_to(self, pose: np.ndarray, agent: np.ndarray, pre: np.ndarray) -> list[np.ndarray]:
        """Shortest clear path agent -> pre-contact point over a visibility graph of the T's corners."""
        cfg = self.cfg
        c = cfg.clearance + 3.0
        rot = _rot(pose[2])
        corners_local = np.array(
            [
                [-60 - c, -c],
                [60 + c, -c],
                [-60 - c, 30 + c],
                [60 + c, 30 + c],
                [-15 - c, 30 + c],
                [15 + c, 30 + c],
                [-15 - c, 120 + c],
                [15 + c, 120 + c],
            ]
        )
        corners = pose[:2] + corners_local @ rot.T
        start = self._retreat_point(pose, agent)
        nodes = [start, pre] + [w for w in corners if 15 <= w[0] <= 497 and 15 <= w[1] <= 497]
        n = len(nodes)
        clear = cfg.clearance - 2.0
        dist = np.full(n, np.inf)
        prev = [-1] * n
        dist[0] = 0.0
        done = np.zeros(n, bool)
        for _ in range(n):  # Dijkstra over a handful of nodes
            i = int(np.argmin(np.where(done, np.inf, dist)))
            if not np.isfinite(dist[i]) or i == 1:
                break
            done[i] = True
            for j in range(n):
                if done[j]:
                    continue
                d = dist[i] + np.linalg.norm(nodes[j] - nodes[i])
                if d < dist[j] and _segment_clear(pose, nodes[i], nodes[j], clear):
                    dist[j], prev[j] = d, i
        if np.isfinite(dist[1]):
            route, k = [], 1
            while k != -1:
                route.append(nodes[k])
                k = prev[k]
            waypoints = [agent] + route[::-1]
        else:  # boxed in (e.g. against a wall): go straight and let the physics sort it out
            waypoints = [agent, start, pre]
        out = []
        for a, b in zip(waypoints[:-1], waypoints[1:]):
            k = int(np.ceil(np.linalg.norm(b - a) / cfg.move_speed))
            out += [a + (b - a) * (i + 1) / k for i in range(k)]
        out += [waypoints[-1]] * 2  # settle at the pre-contact point
        return out

    def _retreat_point(self, pose: np.ndarray, agent: np.ndarray) -> np.ndarray:
        """Where to step first so that the agent is clear of the T (itself if already clear)."""
        want = self.cfg.clearance + 1.0
        d = distance_to_t(pose, agent[None])[0]
        if d >= want:
            return agent
        eps = 0.5
        grad = np.array(
            [
                distance_to_t(pose, (agent + e)[None])[0] - distance_to_t(pose, (agent - e)[None])[0]
                for e in np.eye(2) * eps
            ]
        )
        norm = np.linalg.norm(grad)
        away = grad / norm if norm > 1e-9 else (agent - (pose[:2] + _rot(pose[2]) @ COM_LOCAL))
        away = away / max(np.linalg.norm(away), 1e-9)
        return np.clip(agent + away * (want - d + 2.0), 15.0, 497.0)

    # ---------------------------------------------------------------------------- acting
    def act(self, env: PushTEnv) -> np.ndarray:
        """Next action (2,) for the unwrapped env's current state."""
        if not self.plan:
            self.plan = self._plan_push(env)
            if self.plan and self.rng.random() < self.cfg.pause_prob:
                self.plan = [np.array(env.agent.position)] * int(self.rng.integers(1, 3)) + self.plan
            if not self.plan:  # no improving push found: back off a little and re-plan
                agent = np.array(env.agent.position)
                self.plan = [agent + self.rng.normal(scale=10.0, size=2)]
        return np.asarray(self.plan.pop(0), dtype=np.float64)


def run_expert_episode(env, seed: int, expert: PushTExpert | None = None, max_steps: int = 300) -> dict:
    """Roll the expert out on a (wrapped) Push-T env from `seed` (`lerobot_ocr.experts.rollout`)."""
    return rollout(env, expert or PushTExpert(seed=seed), seed, max_steps)
