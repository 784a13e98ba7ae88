"""Events derived from consecutive occupancy updates, and the dispatcher's bounded fan-out."""

from __future__ import annotations

import asyncio
from typing import Any

from prometheus_client import CollectorRegistry

from service.outputs.events import EventDeriver, SiteUpdate, threshold_crossings
from service.outputs.sink import Dispatcher, OutputMetrics, Sink
from sites import SiteLayout, Zone

LAYOUT = SiteLayout.of(zones=[Zone("entrance", [[0, 0], [2, 0], [2, 2], [0, 2]])])


def occupancy(t: float, people: dict[str, tuple[float, float]], door: tuple[int, int]) -> dict[str, Any]:
    inside = sum(0 <= x <= 2 and 0 <= y <= 2 for x, y in people.values())
    return {"site": "hall", "time": t, "count": len(people),
            "people": [{"track_id": k, "position_m": list(v)} for k, v in people.items()],
            "zones": {"entrance": {"count": inside}}, "lines": {"door": {"in": door[0], "out": door[1]}}}


def test_the_first_update_is_the_baseline_then_changes_are_events() -> None:
    deriver = EventDeriver()
    first = deriver.derive("hall", occupancy(1.0, {"hall:1": (1, 1)}, (4, 1)), LAYOUT)
    assert first.events == () and first.zones == {"entrance": 1}
    second = deriver.derive("hall", occupancy(2.0, {"hall:1": (5, 5), "hall:2": (1, 1)}, (6, 1)), LAYOUT)
    kinds = [(e["type"], e.get("track_id") or e.get("direction")) for e in second.events]
    assert kinds == [("line_crossing", "in"), ("line_crossing", "in"), ("zone_enter", "hall:2"),
                     ("zone_leave", "hall:1")]
    assert second.zones_before == {"entrance": 1}
    assert len({e["id"] for e in second.events}) == 4
    assert all(e["site"] == "hall" and e["time"] == 2.0 for e in second.events)
    # A tally rebuilt lower (a late frame replayed) gives no event, and the next growth counts from it.
    assert deriver.derive("hall", occupancy(3.0, {}, (5, 1)), LAYOUT).of_type("line_crossing") == []
    assert len(deriver.derive("hall", occupancy(4.0, {}, (6, 2)), LAYOUT).of_type("line_crossing")) == 2


def test_zone_thresholds_up_and_down() -> None:
    def update(before: int, after: int) -> SiteUpdate:
        return SiteUpdate("hall", 1.0, {"zones": {"entrance": {"count": after}}}, {"entrance": before})

    assert [e["direction"] for e in threshold_crossings(update(2, 3), {"entrance": 3})] == ["up"]
    assert [e["direction"] for e in threshold_crossings(update(5, 2), {"entrance": 3})] == ["down"]
    assert threshold_crossings(update(3, 4), {"entrance": 3}) == []
    assert threshold_crossings(update(1, 2), {"entrance": 3}) == []
    assert threshold_crossings(update(1, 2), {"elsewhere": 1}) == []


class SlowSink(Sink):
    """Takes updates only once released."""

    name = "slow"

    def __init__(self) -> None:
        self.release = asyncio.Event()
        self.taken: list[float] = []

    async def publish(self, update: SiteUpdate) -> None:
        await self.release.wait()
        self.taken.append(update.time)


class FastSink(SlowSink):
    name = "fast"

    async def publish(self, update: SiteUpdate) -> None:
        self.taken.append(update.time)


def test_a_slow_sink_drops_what_its_queue_cannot_hold_and_slows_nothing_else() -> None:
    async def scenario() -> tuple[list[float], list[float], float, float]:
        registry = CollectorRegistry()
        slow, fast = SlowSink(), FastSink()
        dispatcher = Dispatcher([slow, fast], OutputMetrics(registry), queue_size=3)
        await dispatcher.start()
        for k in range(10):
            dispatcher.offer("hall", occupancy(float(k), {}, (0, 0)), LAYOUT)
            await asyncio.sleep(0.01)
        slow.release.set()
        await dispatcher.close()
        dropped = registry.get_sample_value("fishloc_output_dropped_total", {"sink": "slow"}) or 0.0
        others = registry.get_sample_value("fishloc_output_dropped_total", {"sink": "fast"}) or 0.0
        return slow.taken, fast.taken, dropped, others

    slow_taken, fast_taken, dropped, others = asyncio.run(scenario())
    assert fast_taken == [float(k) for k in range(10)] and others == 0
    assert len(slow_taken) + dropped == 10 and dropped >= 6
    assert slow_taken == sorted(slow_taken)
