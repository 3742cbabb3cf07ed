"""Per-fleet service levels as Prometheus gauges (on ``GET /metrics``).

A collector registered once in the default registry reads, at each scrape,
the service levels (:mod:`routing_svc.service.service_levels`) of the fleets
that each live :class:`~routing_svc.service.fleets.FleetService` of this
process holds in memory; it reads no database. The numbers are those of
``GET /v1/fleets/{id}/metrics``:

- ``routing_svc_fleet_within_threshold{fleet, threshold, scope}``: the
  fraction of targets completed within the threshold (``scope`` ``all`` or
  ``recent``);
- ``routing_svc_fleet_completion_cost{fleet, quantile, scope}``: the 50th,
  90th and 95th percentiles of the completion cost;
- ``routing_svc_fleet_undispatched_total{fleet}``: targets nobody could be sent to in full.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterator
from typing import TYPE_CHECKING

from prometheus_client import REGISTRY
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily
from prometheus_client.registry import Collector

if TYPE_CHECKING:
    from routing_svc.service.fleets import FleetService


class FleetLevelsCollector(Collector):
    """The service levels of the fleets in memory, collected at scrape time."""

    def __init__(self) -> None:
        self._services: weakref.WeakSet[FleetService] = weakref.WeakSet()

    def track(self, service: FleetService) -> None:
        """Report the fleets of ``service`` (until it is garbage)."""
        self._services.add(service)

    def collect(self) -> Iterator[GaugeMetricFamily | CounterMetricFamily]:
        within = GaugeMetricFamily(
            "routing_svc_fleet_within_threshold",
            "Fraction of a fleet's targets completed within a threshold (cost units)",
            labels=["fleet", "threshold", "scope"],
        )
        cost = GaugeMetricFamily(
            "routing_svc_fleet_completion_cost",
            "Percentiles of a fleet's completion cost (the last dispatched vehicle's arrival)",
            labels=["fleet", "quantile", "scope"],
        )
        undispatched = CounterMetricFamily(
            "routing_svc_fleet_undispatched",
            "Targets of a fleet that no available vehicles could be sent to in full",
            labels=["fleet"],
        )
        for service in list(self._services):
            for fleet_id, report in service.cached_service_levels():
                thresholds = report["thresholds"]
                for scope in ("all", "recent"):
                    part = report[scope]
                    for limit, fraction in zip(thresholds, part["within"], strict=True):
                        if fraction is not None:
                            within.add_metric([fleet_id, repr(limit), scope], fraction)
                    for name, value in part["percentiles"].items():
                        if value is not None:
                            q = str(int(name[1:]) / 100)
                            cost.add_metric([fleet_id, q, scope], value)
                undispatched.add_metric([fleet_id], report["all"]["undispatched"])
        yield within
        yield cost
        yield undispatched


COLLECTOR = FleetLevelsCollector()
REGISTRY.register(COLLECTOR)
