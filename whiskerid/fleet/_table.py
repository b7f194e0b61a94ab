"""The fleet's table, ``fleet.csv``: one row per session, read and written atomically."""

import csv
import io
from collections.abc import Iterable
from pathlib import Path

from ..io import atomic_write

#: The table's columns, in order.
COLUMNS = (
    "whisker", "session", "status", "f1_hz", "f1_std", "zeta", "zeta_std", "uncertainty",
    "checks", "n_plucks", "f1_plucks", "zeta_plucks", "f1_pluck_sd", "zeta_pluck_sd",
    "pluck_status", "files", "sha256", "record_sha256", "key", "fitted_at", "fit_s",
)  # fmt: skip
TABLE_NAME = "fleet.csv"
#: The driving health log beside it (``whiskerid fleet drive``), in the same columns.
HEALTH_NAME = "health.csv"


class FleetError(ValueError):
    """A fleet run that cannot start (an output that is not ours, a table not a fleet's)."""


def read_table(path: str | Path) -> list[dict]:
    """The rows of a fleet table (``fleet.csv``), as strings; [] if there is none.

    Raises:
        FleetError: The file is not a fleet table.
    """
    path = Path(path)
    if not path.exists():
        return []
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            if tuple(reader.fieldnames or ()) != COLUMNS:
                raise FleetError(
                    f"{path} is not a fleet table (its header is not whiskerid's); "
                    "give another --out folder"
                )
            return [_mend(row, n, path.name) for n, row in enumerate(reader, start=2)]
    except UnicodeDecodeError as err:
        line = err.object[: err.start].count(b"\n") + 1
        raise FleetError(
            f"{path}: line {line} is not UTF-8 text (byte 0x{err.object[err.start]:02x} "
            "at offset "
            f"{err.start}); mend or remove the file"
        ) from None


def _mend(row: dict, line: int, name: str) -> dict:
    """A row as read; a torn one (too few or too many fields: a table cut by a crash or
    edited by hand) gets the status ``torn row``, and no key, so that the next run fits its
    session again and a check flags it instead of dropping it."""
    if None not in row and all(v is not None for v in row.values()):
        return row
    fields = sum(v is not None for k, v in row.items() if k is not None)
    fields += len(row.get(None) or [])
    mended = {c: row.get(c) or "" for c in COLUMNS}
    checks = f"line {line} of {name} has {fields} of {len(COLUMNS)} fields"
    mended.update(status="torn row", key="", checks=checks)
    return mended


def write_table(path: str | Path, rows: Iterable[dict]) -> Path:
    """Write the rows (sorted by whisker and session) atomically."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in sorted(rows, key=lambda r: (r["whisker"], r["session"])):
        writer.writerow({c: row.get(c, "") for c in COLUMNS})
    return atomic_write(path, buf.getvalue())
