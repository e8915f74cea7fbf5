"""The switch on its own: pure decisions from scores, a threshold and the per-row state (no policy)."""

import pytest
import torch

from lerobot_ocr.policies.ocr_joint.switch import SwitchState, advance, decide, needs_check

NAN = float("nan")


def run(scores: list[list[float]], chunk_size: int, threshold: float = 0.0):
    """Step the switch through (T, B) scores; return per step (modes, actions_left, chunks) as lists."""
    state = SwitchState.start(len(scores[0]))
    trace = []
    for row_scores in scores:
        decision = decide(torch.tensor(row_scores, dtype=torch.float64), threshold, state)
        state = advance(state, decision, chunk_size)
        trace.append((decision.recovering.tolist(), state.actions_left.tolist(), state.chunks.tolist()))
    return trace, state


def test_a_row_enters_below_the_threshold_and_hands_back_only_at_a_chunk_boundary():
    # row 0 OOD at once, back in distribution at step 1 (mid-chunk) and after; row 1 stays in distribution
    trace, state = run([[-1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]], chunk_size=3)
    modes = [t[0][0] for t in trace]
    assert modes == [True, True, True, False]  # the 3-action chunk runs out before the hand-back
    assert [t[1][0] for t in trace] == [2, 1, 0, 0]
    assert all(not t[0][1] for t in trace)
    assert state.handed_back.tolist() == [True, False]


def test_a_row_still_out_of_distribution_gets_a_new_chunk_and_counts_it():
    trace, state = run([[-1.0], [-1.0], [-1.0], [-1.0], [1.0], [-1.0]], chunk_size=2)
    assert [t[0][0] for t in trace] == [True, True, True, True, False, True]
    assert [t[2][0] for t in trace] == [1, 1, 2, 2, 2, 1]  # a new recovery counts its chunks from 0
    assert state.handed_back.tolist() == [True]  # it handed back once, at step 4


def test_a_nan_score_decides_nothing():
    state = SwitchState.start(2)
    first = decide(torch.tensor([-1.0, 1.0], dtype=torch.float64), 0.0, state)
    assert first.enter.tolist() == [True, False] and first.needs_chunk.tolist() == [True, False]
    state = advance(state, first, chunk_size=5)
    state = SwitchState(state.recovering, torch.tensor([3, 0]), state.chunks, state.handed_back)  # mid-chunk
    nothing = decide(torch.tensor([NAN, NAN], dtype=torch.float64), 0.0, state)
    assert nothing.recovering.tolist() == [True, False]  # keeps its mode, hands nothing back
    assert not nothing.enter.any() and not nothing.hand_back.any() and not nothing.needs_chunk.any()


def test_a_recovering_row_at_its_chunks_end_must_be_scored():
    state = advance(
        SwitchState.start(1), decide(torch.tensor([-1.0]), 0.0, SwitchState.start(1)), chunk_size=1
    )
    with pytest.raises(ValueError, match="needs a score"):
        decide(torch.tensor([NAN]), 0.0, state)


def test_when_a_check_is_needed():
    state = SwitchState.start(2)
    assert needs_check(state, 0)  # first step: the base's queue is empty after reset
    assert not needs_check(state, 5)  # every row inside a base chunk
    assert needs_check(state, 0) and needs_check(state, None)  # the base plans now / queue unknown
    recovering = SwitchState(torch.tensor([True, False]), state.actions_left, state.chunks, state.handed_back)
    assert needs_check(recovering, 5)


def test_decide_rejects_scores_for_other_rows():
    with pytest.raises(ValueError, match="one per row"):
        decide(torch.zeros(3), 0.0, SwitchState.start(2))
