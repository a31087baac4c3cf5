"""Prometheus metrics of the planner job (served at /metrics by the process that runs it)."""

from __future__ import annotations

from prometheus_client import Counter, Gauge, Histogram

PLANNER_RUNS = Counter(
    "smoothfleet_planner_runs",
    "Planner cycles by corridor and outcome (published, skipped, failed, busy).",
    ["corridor", "status"],
)
PLANNER_RUN_SECONDS = Histogram(
    "smoothfleet_planner_run_seconds",
    "Wall time of one planner cycle (read, predict, fuse, smooth, bottlenecks, publish).",
    buckets=(0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0),
)
PLANNER_LAST_PUBLISHED = Gauge(
    "smoothfleet_planner_last_published_timestamp_seconds",
    "Unix time of the last published plan, by corridor.",
    ["corridor"],
    multiprocess_mode="max",  # serve's workers each run the schedule: the newest counts
)
PLANNER_INRIX_IGNORED = Gauge(
    "smoothfleet_planner_inrix_ignored",
    "INRIX readings the last cycle refused from its history window, by corridor and reason.",
    ["corridor", "reason"],
    multiprocess_mode="mostrecent",
)
PLANNER_INPUT_PINGS = Gauge(
    "smoothfleet_planner_window_pings",
    "Pings in the last cycle's window, by corridor and where they went: fused on the corridor, "
    "off the corridor, or set aside by the engaged_pings rule.",
    ["corridor", "where"],
    multiprocess_mode="mostrecent",
)
