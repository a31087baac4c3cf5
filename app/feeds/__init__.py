"""Third-party feeds: the INRIX segment-speed feed (endpoint, poller, recorded replays)."""
