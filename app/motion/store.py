"""The MOTION store: Parquet files beside the warehouse, read with DuckDB.

Why not the warehouse: a MOTION day is hundreds of millions of 25 Hz points that are written once
and then only aggregated (Edie boxes over hours and kilometres). Measured by
`bench/motion_import.py --warehouse-points` (docs/performance.md), PostgreSQL's COPY loaded them
3 to 7 times slower than pyarrow wrote Parquet, and the Edie GROUP BY took 5 times longer in
PostgreSQL than in DuckDB on the Parquet file; the fleet's own pings (1 Hz, 100 cars) stay in
the warehouse, and the figure joins the two.

Layout under `SMOOTHFLEET_DATA_DIR/motion` (or `--store`), partitioned by UTC day like the pings:

    points/day=YYYY-MM-DD/<import>.parquet         one row per trajectory point
    trajectories/day=YYYY-MM-DD/<import>.parquet   one row per MOTION document (vehicle fragment)
    imports/<sha256 of the file>.json              what each imported file added (written last)
    staging/<import>/...                           an import in progress (invisible to readers)

A trajectory's points live in the day of its first timestamp. `<import>` is the first 16 hex
digits of the file's SHA-256.
"""

from __future__ import annotations

from pathlib import Path

import duckdb
import pyarrow as pa

from app.core.config import Settings

POINTS = "points"
CELLS = "cells"
TRAJECTORIES = "trajectories"
# The base grid of `cells`: the paper's box. A box whose size is a whole number of cells is
# summed from `cells` (about 100 times fewer rows than points); any other box from `points`.
CELL_T_S = 10.0
CELL_X_M = 200.0
IMPORTS = "imports"
STAGING = "staging"

# One row per trajectory point: the step it stands for (app.motion.kinematics).
POINT_SCHEMA = pa.schema(
    [
        pa.field("trajectory_id", pa.int64()),
        pa.field("t_s", pa.float64()),  # unix seconds
        pa.field("x_m", pa.float32()),  # corridor position
        pa.field("lane", pa.int16()),
        pa.field("speed_mps", pa.float32()),
        pa.field("accel_mps2", pa.float32()),
        pa.field("dt_s", pa.float32()),
        pa.field("dx_m", pa.float32()),
        pa.field("fuel_g", pa.float32()),
    ]
)
# One row per run of a trajectory's points in one lane and one cell of the base grid.
CELL_SCHEMA = pa.schema(
    [
        pa.field("trajectory_id", pa.int64()),
        pa.field("t_cell_s", pa.float64()),  # unix seconds, a multiple of CELL_T_S
        pa.field("x_cell_m", pa.float64()),  # a multiple of CELL_X_M
        pa.field("lane", pa.int16()),
        pa.field("time_s", pa.float64()),
        pa.field("distance_m", pa.float64()),
        pa.field("fuel_g", pa.float64()),
        pa.field("points", pa.int32()),
    ]
)
# One row per MOTION document.
TRAJECTORY_SCHEMA = pa.schema(
    [
        pa.field("trajectory_id", pa.int64()),
        pa.field("document_id", pa.string()),
        pa.field("source_sha256", pa.string()),
        pa.field("first_t_s", pa.float64()),
        pa.field("last_t_s", pa.float64()),
        pa.field("first_x_m", pa.float64()),
        pa.field("last_x_m", pa.float64()),
        pa.field("points", pa.int32()),
        pa.field("lane", pa.int16()),
        pa.field("vehicle_class", pa.int16()),
        pa.field("fuel_model", pa.string()),
        pa.field("length_m", pa.float32()),
        pa.field("width_m", pa.float32()),
        pa.field("height_m", pa.float32()),
        pa.field("direction", pa.int8()),
        pa.field("x_score", pa.float32()),
        pa.field("y_score", pa.float32()),
        pa.field("is_fleet", pa.bool_()),
        pa.field("distance_m", pa.float64()),
        pa.field("fuel_g", pa.float64()),
    ]
)


def motion_store(settings: Settings) -> Path:
    """Where the MOTION store lives: SMOOTHFLEET_MOTION_DIR, else DATA_DIR/motion."""
    return settings.motion_dir or settings.data_dir / "motion"


def imported_days(store: Path) -> list[str]:
    """The UTC days (YYYY-MM-DD) holding imported trajectories, latest first."""
    days = {path.parent.name.removeprefix("day=") for path in files(store, TRAJECTORIES)}
    return sorted(days, reverse=True)


class MotionStoreEmpty(LookupError):
    """Nothing has been imported into this store yet."""


def files(store: Path, table: str) -> list[Path]:
    """The committed Parquet files of one table."""
    return sorted((store / table).glob("day=*/*.parquet"))


def _relation(store: Path, table: str, schema: pa.Schema) -> str:
    paths = files(store, table)
    if not paths:
        columns = ", ".join(
            f"CAST(NULL AS {_duck_type(field.type)}) AS {field.name}" for field in schema
        )
        return f"SELECT {columns}, CAST(NULL AS DATE) AS day WHERE false"
    pattern = str(store / table / "day=*" / "*.parquet").replace("'", "''")
    return f"SELECT * FROM read_parquet('{pattern}', hive_partitioning = true)"


def _duck_type(arrow_type: pa.DataType) -> str:
    names = {
        pa.int8(): "TINYINT",
        pa.int16(): "SMALLINT",
        pa.int32(): "INTEGER",
        pa.int64(): "BIGINT",
        pa.float32(): "REAL",
        pa.float64(): "DOUBLE",
        pa.bool_(): "BOOLEAN",
        pa.string(): "VARCHAR",
    }
    return names[arrow_type]


def view_sql(store: Path) -> str:
    """The DuckDB views and macros over a store (also written to `<store>/views.sql`)."""
    return "\n".join(
        [
            f"CREATE OR REPLACE VIEW motion_points AS {_relation(store, POINTS, POINT_SCHEMA)};",
            f"CREATE OR REPLACE VIEW motion_cells AS {_relation(store, CELLS, CELL_SCHEMA)};",
            "CREATE OR REPLACE VIEW motion_trajectories AS "
            f"{_relation(store, TRAJECTORIES, TRAJECTORY_SCHEMA)};",
            EDIE_MACRO,
            EDIE_CELLS_MACRO,
        ]
    )


def _edie_macro(
    name: str, table: str, t: str, x: str, time: str, distance: str, fuel: str, points: str
) -> str:
    """Edie's generalised definitions (paper, "Results") on boxes of h_t x h_x over `table`.

    Boxes are aligned to multiples of h_t since the epoch and of h_x from the corridor's start,
    so they agree between queries; `vehicles` counts distinct trajectories.
    """
    return f"""
CREATE OR REPLACE MACRO {name}(
    since_s, until_s, x_from_m, x_to_m, h_t_s := 10.0, h_x_m := 200.0, lane_no := NULL
) AS TABLE
SELECT
    floor({t} / h_t_s) * h_t_s AS t_start_s,
    floor({x} / h_x_m) * h_x_m AS x_start_m,
    sum({time}) AS time_s,
    sum({distance}) AS distance_m,
    sum({fuel}) AS fuel_g,
    count(DISTINCT trajectory_id) AS vehicles,
    {points} AS points,
    sum({time}) / (h_t_s * h_x_m) AS density_veh_per_m,
    sum({distance}) / (h_t_s * h_x_m) AS flow_veh_per_s,
    sum({fuel}) / (h_t_s * h_x_m) AS fuel_rate_density_g_per_s_m,
    sum({distance}) / nullif(sum({time}), 0) AS speed_mps,
    sum({fuel}) / nullif(sum({time}), 0) AS fuel_rate_per_vehicle_g_per_s,
    sum({fuel}) / nullif(sum({distance}), 0) AS fuel_per_distance_g_per_m
FROM {table}
WHERE {t} >= since_s AND {t} < until_s
  AND {x} >= x_from_m AND {x} < x_to_m
  AND (lane_no IS NULL OR lane = lane_no)
GROUP BY ALL;
"""


# Every point: any box size.
EDIE_MACRO = _edie_macro(
    "motion_edie", "motion_points", "t_s", "x_m", "dt_s", "dx_m", "fuel_g", "count(*)"
)
# The same sums regrouped from `cells`, for boxes of whole cells (h_t a multiple of 10 s, h_x of
# 200 m).
EDIE_CELLS_MACRO = _edie_macro(
    "motion_edie_cells",
    "motion_cells",
    "t_cell_s",
    "x_cell_m",
    "time_s",
    "distance_m",
    "fuel_g",
    "sum(points)",
)


def connect(store: Path) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB connection with the store's views and the `motion_edie` macro."""
    connection = duckdb.connect(":memory:")
    connection.execute(view_sql(store))
    return connection


def write_views_file(store: Path) -> Path:
    """`<store>/views.sql`: analysts open the store with `duckdb -init <store>/views.sql`."""
    path = store / "views.sql"
    path.write_text(view_sql(store) + "\n")
    return path
