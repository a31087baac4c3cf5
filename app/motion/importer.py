"""`smoothfleet motion import`: MOTION files into the store, once, with every refusal explained.

Each file is read in batches (app.motion.documents), so memory depends on the batch, not on the
file. Each document is checked; a bad one is counted with its reason and the rest of the file is
imported. Positions go through the `MotionFrame` onto the corridor (sim.motion.frame), each point
gets the step it stands for in Edie's sums (app.motion.kinematics), and the rows are written to
Parquet in a staging folder that becomes visible only when the file is done (app.motion.store).

Re-importing adds nothing: a file whose SHA-256 is already in `imports/` is skipped, and a
document whose `_id` is already in the store (from another file) is counted as a duplicate.
If the file's JSON structure breaks part-way, the documents before the break are kept and the
report says where it broke.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from numpy.typing import NDArray

from app.motion.documents import (
    BadDocument,
    DocumentBatch,
    MotionFileError,
    open_motion_file,
    parse_batch,
    split_documents,
)
from app.motion.kinematics import cell_runs, fuel_model_name, trajectory_steps
from app.motion.store import (
    CELL_SCHEMA,
    CELL_T_S,
    CELL_X_M,
    CELLS,
    IMPORTS,
    POINT_SCHEMA,
    POINTS,
    STAGING,
    TRAJECTORIES,
    TRAJECTORY_SCHEMA,
    files,
    write_views_file,
)
from contract.units import FEET_PER_MILE, METRES_PER_FOOT
from sim.motion.frame import MotionFrame

IntArray = NDArray[np.int64]
SECONDS_PER_DAY = 86_400
# MOTION timestamps are unix seconds; one outside these years is a unit mistake (milliseconds
# read as seconds lie some 50,000 years ahead) and no day of the store could hold it.
EARLIEST_UNIX_S = 0.0  # 1970-01-01 UTC
LATEST_UNIX_S = 4_102_444_800.0  # 2100-01-01 UTC
# MOTION positions are feet along I-24 (x, its mileposts x 5,280: the testbed near mile 60) and
# across it from the median (y, a few lanes either side). A point beyond I-24's length in
# Tennessee (about 185 miles), or further across than any roadway, is a unit or data mistake:
# one point at 1e9 m sized the day figure's grid at 5 M boxes a column, and a point of 1e300 ft
# was stored as an infinite x with NaN fuel.
MAX_X_FT = 200 * FEET_PER_MILE
# The store keeps a vehicle class in 16 bits (MOTION's coarse classes are single digits).
MAX_VEHICLE_CLASS = 32_767
MAX_ABS_Y_FT = 500.0
# The manifest keeps this many bad documents' reasons (the counts are always complete).
REASONS_KEPT = 1000
HASH_CHUNK_BYTES = 8 * 1024 * 1024
DICTIONARY_COLUMNS = ["trajectory_id", "lane", "document_id", "source_sha256", "fuel_model"]


@dataclass
class ImportReport:
    """What one file added to the store, and what it did not and why."""

    path: Path
    sha256: str
    documents: int = 0
    points: int = 0
    duplicates: int = 0
    other_direction: int = 0
    bad: list[BadDocument] = field(default_factory=list)
    already_imported: bool = False
    file_error: str | None = None
    seconds: float = 0.0

    @property
    def points_per_s(self) -> float:
        """Import speed."""
        return self.points / self.seconds if self.seconds > 0 else 0.0


def file_sha256(path: Path) -> str:
    """SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open_motion_file(path) as stream:
        while chunk := stream.read(HASH_CHUNK_BYTES):
            digest.update(chunk)
    return digest.hexdigest()


def trajectory_key(document_id: str) -> int:
    """A 64-bit key for a MOTION `_id` (BLAKE2b), joining points to their trajectory."""
    digest = hashlib.blake2b(document_id.encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big", signed=True)


def import_motion_file(
    path: Path,
    store: Path,
    frame: MotionFrame | None = None,
    progress: Callable[[int], None] | None = None,
) -> ImportReport:
    """Import one MOTION file into `store`; `progress` is called with the bytes read so far."""
    frame = frame or MotionFrame()
    started = time.perf_counter()
    report = ImportReport(path=path, sha256=file_sha256(path))
    manifest = store / IMPORTS / f"{report.sha256}.json"
    if manifest.exists():
        report.already_imported = True
        report.seconds = time.perf_counter() - started
        return report
    name = report.sha256[:16]
    _remove_unfinished(store, name)
    staging = store / STAGING / name
    staging.mkdir(parents=True)
    writer = _DayWriters(staging, name)
    known = _known_trajectories(store)
    try:
        with open_motion_file(path) as stream:
            for batch in split_documents(stream):
                _import_batch(batch, frame, known, writer, report)
                if progress is not None:
                    progress(batch.bytes_read)
    except MotionFileError as error:
        report.file_error = str(error)
    finally:
        writer.close()
    _commit(store, staging)
    report.seconds = time.perf_counter() - started
    manifest.parent.mkdir(parents=True, exist_ok=True)
    manifest.write_text(json.dumps(_manifest(report), indent=1))
    write_views_file(store)
    return report


def _import_batch(
    batch: DocumentBatch,
    frame: MotionFrame,
    known: set[int],
    writer: _DayWriters,
    report: ImportReport,
) -> None:
    """Check a batch's documents, then write the good ones' points, cells and trajectories."""
    table, indices = parse_batch(batch)
    report.bad.extend(batch.bad)
    accepted = _accept(
        table, indices, dict(zip(batch.indices, batch.offsets, strict=True)), frame, known, report
    )
    if accepted is None:
        return
    tables, days, lengths, first_points = _tables(accepted, frame, report.sha256)
    for day in np.unique(days):
        in_day = days == day
        if in_day.all():
            writer.write(int(day), tables)
            continue
        point_in_day = np.repeat(in_day, lengths)
        writer.write(
            int(day),
            {
                POINTS: tables[POINTS].filter(pa.array(point_in_day)),
                CELLS: tables[CELLS].filter(pa.array(point_in_day[first_points])),
                TRAJECTORIES: tables[TRAJECTORIES].filter(pa.array(in_day)),
            },
        )
    report.documents += len(accepted.keys)
    report.points += len(accepted.time_s)


@dataclass(frozen=True, slots=True)
class _Accepted:
    """The documents of a batch that passed every check and are new to the store."""

    table: pa.Table
    document_ids: list[str]
    keys: IntArray
    lengths: IntArray
    time_s: NDArray[np.float64]
    x_ft: NDArray[np.float64]
    y_ft: NDArray[np.float64]

    @property
    def starts(self) -> IntArray:
        """Index of each document's first point."""
        starts: IntArray = np.concatenate([[0], np.cumsum(self.lengths)[:-1]]).astype(np.int64)
        return starts


def _accept(
    table: pa.Table,
    indices: list[int],
    offsets: dict[int, int],
    frame: MotionFrame,
    known: set[int],
    report: ImportReport,
) -> _Accepted | None:
    """The documents to import; the others counted in `report` (bad with their reason,
    other direction, duplicates). `known` gains the accepted documents' keys."""
    if table.num_rows == 0:
        return None
    document_ids = pc.struct_field(table.column("_id"), "$oid").to_pylist()
    counts = {
        column: pc.fill_null(pc.list_value_length(table.column(column)), -1).to_numpy()
        for column in ("timestamp", "x_position", "y_position")
    }
    direction = pc.fill_null(table.column("direction"), 0).to_numpy()
    # stored as int16: a larger class wrapped silently (70000 became 4464)
    vehicle_class = pc.fill_null(table.column("coarse_vehicle_class"), -1).to_numpy()
    keep = np.ones(table.num_rows, dtype=bool)

    def refuse(row: int, reason: str) -> None:
        keep[row] = False
        report.bad.append(BadDocument(indices[row], offsets[indices[row]], reason))

    for row in range(table.num_rows):
        reason = _shape_problem(
            document_ids[row],
            counts["timestamp"][row],
            counts["x_position"][row],
            counts["y_position"][row],
            int(direction[row]),
        )
        if not reason and not -1 <= vehicle_class[row] <= MAX_VEHICLE_CLASS:
            reason = (
                f"coarse_vehicle_class {vehicle_class[row]} is no vehicle class "
                f"(0 to {MAX_VEHICLE_CLASS:,})"
            )
        if reason:
            refuse(row, reason)
        elif direction[row] != frame.direction:
            keep[row] = False
            report.other_direction += 1
    if not keep.any():  # a batch of the other direction or of bad documents only
        return None
    shaped = table.filter(pa.array(keep)) if not keep.all() else table
    rows = np.flatnonzero(keep)
    lengths = counts["timestamp"][keep].astype(np.int64)
    time_s = _flat(shaped, "timestamp")
    x_ft = _flat(shaped, "x_position")
    y_ft = _flat(shaped, "y_position")
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    # Point-level checks, reduced per document.
    finite = np.isfinite(time_s) & np.isfinite(x_ft) & np.isfinite(y_ft)
    with np.errstate(invalid="ignore"):
        in_era = (time_s >= EARLIEST_UNIX_S) & (time_s < LATEST_UNIX_S)
        on_road = (x_ft >= 0.0) & (x_ft <= MAX_X_FT) & (np.abs(y_ft) <= MAX_ABS_Y_FT)
    step_ok = np.ones(len(time_s), dtype=bool)
    step_ok[1:] = np.diff(time_s) > 0
    step_ok[starts] = True
    good_points = finite & in_era & on_road & step_ok
    doc_ok = np.logical_and.reduceat(good_points, starts) if len(starts) else np.zeros(0, bool)
    for position in np.flatnonzero(~doc_ok):
        first = starts[position]
        broken = int(np.argmax(~good_points[first : first + lengths[position]]))
        if not finite[first + broken]:
            reason = f"non-finite or null value at point {broken}"
        elif not in_era[first + broken]:
            reason = (
                f"timestamp {time_s[first + broken]:.15g} at point {broken} is no time in "
                "seconds between 1970 and 2100 (milliseconds?)"
            )
        elif not on_road[first + broken]:
            reason = (
                f"position ({x_ft[first + broken]:.15g}, {y_ft[first + broken]:.15g}) ft at point "
                f"{broken} is not on I-24 (x 0 to {MAX_X_FT:,.0f} ft along it, y within "
                f"{MAX_ABS_Y_FT:.0f} ft across; metres?)"
            )
        else:
            reason = f"timestamps do not increase at point {broken}"
        refuse(int(rows[position]), reason)
    keys = np.array([trajectory_key(document_ids[row]) for row in rows], dtype=np.int64)
    fresh = doc_ok.copy()
    for position in np.flatnonzero(doc_ok):
        key = int(keys[position])
        if key in known:
            fresh[position] = False
            report.duplicates += 1
        else:
            known.add(key)
    if not fresh.any():
        return None
    point_keep = np.repeat(fresh, lengths)
    return _Accepted(
        table=shaped.filter(pa.array(fresh)) if not fresh.all() else shaped,
        document_ids=[document_ids[row] for row in rows[fresh]],
        keys=keys[fresh],
        lengths=lengths[fresh],
        time_s=time_s[point_keep],
        x_ft=x_ft[point_keep],
        y_ft=y_ft[point_keep],
    )


def _tables(
    accepted: _Accepted, frame: MotionFrame, sha256: str
) -> tuple[dict[str, pa.Table], IntArray, IntArray, IntArray]:
    """Points, cells and trajectories of accepted documents; each document's UTC day (days
    since the epoch), its point count, and each cell row's first point."""
    table, keys, lengths, time_s = accepted.table, accepted.keys, accepted.lengths, accepted.time_s
    starts = accepted.starts
    vehicle_class = pc.fill_null(table.column("coarse_vehicle_class"), -1).to_numpy()
    x_m = frame.x_m(accepted.x_ft)
    lane = frame.lane(accepted.y_ft)
    steps = trajectory_steps(time_s, x_m, starts, np.repeat(vehicle_class, lengths))
    trajectory_of_point = np.repeat(keys, lengths)
    points = pa.table(
        {
            "trajectory_id": trajectory_of_point,
            "t_s": time_s,
            "x_m": x_m.astype(np.float32),
            "lane": lane,
            "speed_mps": steps.speed_mps.astype(np.float32),
            "accel_mps2": steps.accel_mps2.astype(np.float32),
            "dt_s": steps.dt_s.astype(np.float32),
            "dx_m": steps.dx_m.astype(np.float32),
            "fuel_g": steps.fuel_g.astype(np.float32),
        },
        schema=POINT_SCHEMA,
    )
    ends = starts + lengths - 1
    feet = np.float32(METRES_PER_FOOT)
    trajectories = pa.table(
        {
            "trajectory_id": keys,
            "document_id": accepted.document_ids,
            "source_sha256": [sha256] * len(keys),
            "first_t_s": time_s[starts],
            "last_t_s": time_s[ends],
            "first_x_m": x_m[starts],
            "last_x_m": x_m[ends],
            "points": lengths.astype(np.int32),
            "lane": lane[starts + lengths // 2],
            "vehicle_class": vehicle_class.astype(np.int16),
            "fuel_model": [fuel_model_name(int(code)) for code in vehicle_class],
            "length_m": _column(table, "length") * feet,
            "width_m": _column(table, "width") * feet,
            "height_m": _column(table, "height") * feet,
            "direction": np.full(len(keys), frame.direction, dtype=np.int8),
            "x_score": _column(table, "x_score"),
            "y_score": _column(table, "y_score"),
            "is_fleet": pc.fill_null(table.column("smoothfleet_fleet"), False).to_numpy(
                zero_copy_only=False
            ),
            "distance_m": np.add.reduceat(steps.dx_m, starts),
            "fuel_g": np.add.reduceat(steps.fuel_g, starts),
        },
        schema=TRAJECTORY_SCHEMA,
    )
    runs = cell_runs(time_s, x_m, lane, trajectory_of_point, steps, CELL_T_S, CELL_X_M)
    cells = pa.table(
        {
            "trajectory_id": trajectory_of_point[runs.first_point],
            "t_cell_s": runs.t_cell_s,
            "x_cell_m": runs.x_cell_m,
            "lane": lane[runs.first_point],
            "time_s": runs.time_s,
            "distance_m": runs.distance_m,
            "fuel_g": runs.fuel_g,
            "points": runs.points.astype(np.int32),
        },
        schema=CELL_SCHEMA,
    )
    days = (time_s[starts] // SECONDS_PER_DAY).astype(np.int64)
    tables = {POINTS: points, CELLS: cells, TRAJECTORIES: trajectories}
    return tables, days, lengths, runs.first_point


def _shape_problem(
    document_id: str | None, timestamps: int, x_positions: int, y_positions: int, direction: int
) -> str | None:
    """Why a document cannot be a trajectory, from its shape alone (None when it can)."""
    if not document_id:
        return "no _id.$oid"
    for name, count in (
        ("timestamp", timestamps),
        ("x_position", x_positions),
        ("y_position", y_positions),
    ):
        if count < 0:
            return f"no {name} array"
    if not timestamps == x_positions == y_positions:
        return (
            f"timestamp, x_position and y_position differ in length "
            f"({timestamps}, {x_positions}, {y_positions})"
        )
    if timestamps == 0:
        return "no points"
    if direction not in (-1, 1):
        return "direction must be -1 (westbound) or 1 (eastbound)"
    return None


def _flat(table: pa.Table, column: str) -> NDArray[np.float64]:
    values = pc.list_flatten(table.column(column))
    result: NDArray[np.float64] = values.to_numpy()  # nulls become NaN
    return result


def _column(table: pa.Table, column: str) -> NDArray[np.float32]:
    values = pc.fill_null(table.column(column), float("nan")).to_numpy()
    result: NDArray[np.float32] = values.astype(np.float32)
    return result


class _DayWriters:
    """One Parquet file per table and UTC day, in the staging folder."""

    SCHEMAS = {POINTS: POINT_SCHEMA, CELLS: CELL_SCHEMA, TRAJECTORIES: TRAJECTORY_SCHEMA}

    def __init__(self, staging: Path, name: str) -> None:
        self.staging = staging
        self.name = name
        self.writers: dict[tuple[int, str], pq.ParquetWriter] = {}

    def write(self, day: int, tables: dict[str, pa.Table]) -> None:
        label = datetime.fromtimestamp(day * SECONDS_PER_DAY, UTC).date().isoformat()
        for table_name, table in tables.items():
            writer = self.writers.get((day, table_name))
            if writer is None:
                folder = self.staging / table_name / f"day={label}"
                folder.mkdir(parents=True)
                writer = self.writers[(day, table_name)] = pq.ParquetWriter(
                    folder / f"{self.name}.parquet",
                    self.SCHEMAS[table_name],
                    # Positions and times hardly repeat: dictionary encoding them is wasted
                    # work; the keys, lanes and names do.
                    use_dictionary=DICTIONARY_COLUMNS,
                )
            writer.write_table(table)

    def close(self) -> None:
        for writer in self.writers.values():
            writer.close()


def _known_trajectories(store: Path) -> set[int]:
    """Keys of every trajectory already in the store."""
    known: set[int] = set()
    for path in files(store, TRAJECTORIES):
        keys = pq.read_table(path, columns=["trajectory_id"]).column("trajectory_id")
        known.update(keys.to_numpy().tolist())
    return known


def _remove_unfinished(store: Path, name: str) -> None:
    """Files of an earlier import of the same file that stopped before its manifest."""
    for table in (POINTS, CELLS, TRAJECTORIES):
        for path in (store / table).glob(f"day=*/{name}.parquet"):
            path.unlink()
    shutil.rmtree(store / STAGING / name, ignore_errors=True)


def _commit(store: Path, staging: Path) -> None:
    """Move the staged files into place: trajectories last, as dedup reads them."""
    for table in (POINTS, CELLS, TRAJECTORIES):
        for path in sorted((staging / table).glob("day=*/*.parquet")):
            target = store / table / path.parent.name / path.name
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, target)
    shutil.rmtree(staging, ignore_errors=True)


def _manifest(report: ImportReport) -> dict[str, Any]:
    return {
        "file": str(report.path),
        "sha256": report.sha256,
        "imported_at": datetime.now(UTC).isoformat(),
        "documents": report.documents,
        "points": report.points,
        "duplicates": report.duplicates,
        "other_direction": report.other_direction,
        "bad_documents": len(report.bad),
        "bad": [
            {"index": bad.index, "offset": bad.offset, "reason": bad.reason}
            for bad in report.bad[:REASONS_KEPT]
        ],
        "file_error": report.file_error,
        "seconds": round(report.seconds, 3),
    }
