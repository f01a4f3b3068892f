"""The loop's CPU accounting for benches (``server.stage_cpu``): what a message arriving while the loop is
busy waits behind is the span it lands in, so long spans weigh by their length."""

from __future__ import annotations

import trio

from server.stage_cpu import DeafSpans


def test_a_busy_instant_falls_in_the_long_span_when_it_holds_most_of_the_cpu() -> None:
    deaf = DeafSpans()
    deaf.spans = [0.001] * 9 + [0.010]  # 9 ms in short spans, 10 ms in one
    assert deaf.report() == {"p50": 10.0, "p99": 10.0, "max": 10.0}
    deaf.spans = [0.001] * 90 + [0.010]  # 90 ms in short spans: half the busy time is in them
    assert deaf.report() == {"p50": 1.0, "p99": 10.0, "max": 10.0}
    assert deaf.report() == {"p50": 0.0, "p99": 0.0, "max": 0.0}  # nothing since the last report


def test_the_spans_are_the_loops_batches_between_two_polls_of_the_sockets() -> None:
    deaf = DeafSpans()

    async def main() -> None:
        trio.lowlevel.add_instrument(deaf)
        for _ in range(5):
            await trio.sleep(0)

    trio.run(main)
    assert len(deaf.spans) >= 5 and all(s >= 0 for s in deaf.spans)
