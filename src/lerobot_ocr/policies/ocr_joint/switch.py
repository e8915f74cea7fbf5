"""The OCR switch: per batch row, run the base policy or the recovery.

The paper's joint policy (arXiv 2411.03294, "joint policy"): pi_joint = pi_b if eta_rec >= eps_rec,
else pi_inv, with eta_rec the keypoints' density score and eps_rec the threshold (here: the manifold's
`score` and its calibrated `threshold_`). As in the paper, a recovering row re-decides once its
recovery chunk has run. Rows on the base are checked when the base is about to plan its next chunk,
and at every step while any row of the batch recovers (the score is computed for the whole batch at
once): a row on the base whose object leaves the distribution then enters recovery at once.

This module is pure: `SwitchState` holds what the switch remembers per row, `decide` maps a score, the
threshold and a state to a `Decision`, `advance` gives the state after the step. No policy, no
networks: `OcrJointPolicy.select_action` scores, calls these, plans the chunks they ask for and mixes.
Shapes: B = batch rows; tensors are 1-D (B,) on one device.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import torch


@dataclass(frozen=True)
class SwitchState:
    """What the switch remembers per row between steps.

    recovering: (B,) bool, the row runs the recovery policy.
    actions_left: (B,) long, recovery actions of the current chunk still to execute (0: it needs a
        decision, and a new chunk if it keeps recovering).
    chunks: (B,) long, recovery chunks planned since the row last entered recovery.
    handed_back: (B,) bool, the row has handed the object back to the base at least once.
    """

    recovering: torch.Tensor
    actions_left: torch.Tensor
    chunks: torch.Tensor
    handed_back: torch.Tensor

    @classmethod
    def start(cls, batch_size: int, device: torch.device | str = "cpu") -> SwitchState:
        """Every row on the base, nothing queued: the state at the start of an episode."""

        def flags():
            return torch.zeros(batch_size, dtype=torch.bool, device=device)

        def counts():
            return torch.zeros(batch_size, dtype=torch.long, device=device)

        return cls(recovering=flags(), actions_left=counts(), chunks=counts(), handed_back=flags())

    @property
    def batch_size(self) -> int:
        return self.recovering.shape[0]

    @cached_property
    def n_recovering(self) -> int:
        """How many rows recover (computed once per state: states are never changed in place)."""
        return int(self.recovering.sum())


@dataclass(frozen=True)
class Decision:
    """The switch's decision for one step, per row (all (B,) bool).

    recovering: the row runs the recovery policy at this step.
    enter: the row leaves the base for the recovery at this step.
    hand_back: the row returns to the base at this step (its recovery chunk has run and the object
        is in distribution again).
    needs_chunk: the row needs a new recovery chunk before it acts.
    """

    recovering: torch.Tensor
    enter: torch.Tensor
    hand_back: torch.Tensor
    needs_chunk: torch.Tensor


def needs_check(state: SwitchState, base_queued: int | None) -> bool:
    """Whether this step needs the score: a recovering row, or a base about to plan (its queue is
    empty, as at an episode's first step after `reset`).

    base_queued: actions the base will pop before it plans again (None: unknown, so always check).
    """
    return state.n_recovering > 0 or not base_queued


def decide(
    score: torch.Tensor, threshold: float, state: SwitchState, handback_ok: torch.Tensor | None = None
) -> Decision:
    """The switch for one step: (B,) scores (NaN = not evaluated), the threshold and the state -> Decision.

    A recovering row whose chunk has run (`actions_left == 0`) hands back when score >= threshold,
    else it needs a new chunk; a row on the base enters recovery (and needs a chunk) when score <
    threshold. A NaN score decides nothing: a row on the base stays there, a recovering row goes on
    with its chunk. `handback_ok` ((B,) bool, optional) is a second test a recovering row must also pass
    to hand back (the joint keypoint density's); entering is the score's alone.

    Raises:
        ValueError: `score` (or `handback_ok`) is not (B,) for the state's B rows, or `score` is NaN
            for a recovering row whose chunk has run (it has no action left, so it must be scored).
    """
    if score.shape != state.recovering.shape:
        raise ValueError(
            f"score has shape {tuple(score.shape)}, expected ({state.batch_size},): one per row."
        )
    score = score.to(state.recovering.device)
    chunk_done = state.recovering & (state.actions_left == 0)
    if bool((chunk_done & score.isnan()).any()):
        raise ValueError("A recovering row whose chunk has run needs a score (got NaN): score every row.")
    hand_back = chunk_done & (score >= threshold)
    if handback_ok is not None:
        if handback_ok.shape != state.recovering.shape:
            raise ValueError(
                f"handback_ok has shape {tuple(handback_ok.shape)}, expected ({state.batch_size},): one "
                "per row."
            )
        hand_back = hand_back & handback_ok.to(hand_back.device)
    enter = ~state.recovering & (score < threshold)
    recovering = (state.recovering & ~hand_back) | enter
    return Decision(recovering, enter, hand_back, enter | (chunk_done & ~hand_back))


def advance(state: SwitchState, decision: Decision, chunk_size: int) -> SwitchState:
    """The state after this step: new chunks hold `chunk_size` actions, each recovering row executes one.

    The recovery action a row executes at this step is its chunk's `chunk_size - 1 - actions_left`
    (actions_left of the returned state).
    """
    left = torch.where(
        decision.needs_chunk, torch.full_like(state.actions_left, chunk_size), state.actions_left
    )
    left = torch.where(decision.recovering, left - 1, left)
    chunks = (
        torch.where(decision.enter, torch.zeros_like(state.chunks), state.chunks)
        + decision.needs_chunk.long()
    )
    return SwitchState(decision.recovering, left, chunks, state.handed_back | decision.hand_back)
