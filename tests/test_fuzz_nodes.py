"""Bounded fuzz of every node's callbacks (the long run: ``cone-perception fuzz``, README)."""

from __future__ import annotations

import pytest

from cone_perception.rostools.fuzz import TARGETS, fuzz_target

N = 150


@pytest.mark.parametrize("target", TARGETS)
def test_no_malformed_message_escapes_and_every_one_is_counted(target: str) -> None:
    rep = fuzz_target(target, N, seed=7)
    assert rep.crashes == 0, rep.crash_examples
    assert rep.messages == N and rep.counted == N, rep.line()
    assert sum(rep.dropped.values()) > N / 2  # the messages are mostly bad: they were dropped, not processed
    if target.endswith("compressed"):
        assert rep.bombs > 10 and rep.dropped.get("too_large", 0) >= rep.bombs
