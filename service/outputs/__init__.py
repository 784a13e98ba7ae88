"""Occupancy out to the building: one concept, three sinks fed by the same site updates.

    tracker host (SiteHub, or the `fishloc sites` worker)
        └─ Dispatcher.offer(site, occupancy, layout)      events derived once (events.py)
               ├─ MqttSink      retained counts, events, Home Assistant discovery (mqtt.py)
               ├─ WebhookSink   signed posts through a durable outbox (webhooks.py)
               └─ HistorySink   per-minute rows in the registry's database (history.py)

The trackers know none of the sinks: whoever runs a tracker hands each occupancy update to the
dispatcher. A new output is a new `Sink` in a new file.
"""

from service.outputs.events import EventDeriver, SiteUpdate
from service.outputs.sink import Dispatcher, OutputMetrics, Sink

__all__ = ["Dispatcher", "EventDeriver", "OutputMetrics", "Sink", "SiteUpdate"]
