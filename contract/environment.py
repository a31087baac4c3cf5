"""The environment variables of this project's programs, which share one prefix.

The server reads `SMOOTHFLEET_<SETTING>`, the car `SMOOTHFLEET_AGENT_<SETTING>`, and a few tools
one name each under the same prefix. A misspelt name reaches no program and its setting keeps
its default without a word, so each program refuses a name under its own prefix that it does
not know; for that the server must know which names are the others'.
"""

from __future__ import annotations

SERVER_ENV_PREFIX = "SMOOTHFLEET_"
AGENT_ENV_PREFIX = "SMOOTHFLEET_AGENT_"

# Read by the project's tools, not by the server: the test suite's external PostgreSQL
# (tests/conftest.py), the shared data for `smoothfleet sim` (sim.drives), the CLI's tracebacks
# (smoothfleet.cli.main) and the benchmarks' stall probe (bench/stall_probe).
TOOL_VARIABLES = frozenset(
    {
        "SMOOTHFLEET_TEST_DATABASE_URL",
        "SMOOTHFLEET_SHARED_DATA",
        "SMOOTHFLEET_DEBUG",
        "SMOOTHFLEET_STALL_LOG",
    }
)

# The agent's settings (`vehicle_agent.settings.AgentSettings`, each under AGENT_ENV_PREFIX;
# tests/vehicle_agent hold the two lists equal). The server has settings under the same prefix
# (`agent_ping_period_s`, the periods it hands the cars), so it cannot pass over the prefix
# whole: a misspelt `SMOOTHFLEET_AGENT_PING_PERIOD` of its own was ignored without a word.
AGENT_VARIABLES = frozenset(
    AGENT_ENV_PREFIX + name
    for name in (
        "BUTTON_BOARD",
        "CAN",
        "DBC_CACHE_DIR",
        "GPIO_ROOT",
        "GPS",
        "HTTP_TIMEOUT_S",
        "LOG_LEVEL",
        "MAKE",
        "POLICY_DIR",
        "SERVER_URL",
        "SPOOL_MAX_ROWS",
        "SPOOL_PATH",
        "TOKEN",
        "VEHICLE_ID",
        "WAVE_SPEED_MPS",
    )
)
