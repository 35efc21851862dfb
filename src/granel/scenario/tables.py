"""The tables a scenario refers to (granule tables, load tables), read by the one reader of
users' files (`guard.reading`): an unknown column is an error, and every error names the file,
the line and the column."""

from __future__ import annotations

from pathlib import Path

GRANULE_COLUMNS, GRANULE_OPTIONAL = ("label", "x", "y", "radius"), ("material",)


def read_granules_table(path: Path) -> list[dict]:
    """A granule table (CSV with a header: label, x, y, radius[, material]), read by the one
    reader (`guard.reading.read_csv`: an unknown or misspelt column is an error). Every value is
    checked: a non-empty label, unique in the file, finite x and y, a finite positive radius;
    the error names the file, the line and the column."""
    from ..guard.reading import InputFileError, number, read_csv

    rows, seen = [], {}
    for r in read_csv(path, "granules_file", GRANULE_COLUMNS, GRANULE_OPTIONAL):
        line = r["__line__"]
        where = f"granules_file {path}, line {line}"
        label = r["label"]
        if not label:
            raise InputFileError(f"{where}: empty label")
        if label in seen:
            raise InputFileError(f"{where}: label {label!r} repeats line {seen[label]}")
        seen[label] = line
        rows.append({"label": label, "material": r.get("material", ""), "x": number(r["x"], where, "x"),
                     "y": number(r["y"], where, "y"), "radius": number(r["radius"], where, "radius", positive=True)})
    if not rows:
        raise InputFileError(f"granules_file {path}: no granules (a row per granule after the header)")
    return rows


def read_load_table(path: Path):
    """A load table (CSV: time [s], force [N]; a header line naming the columns `time,force` is
    optional, `#` comments are allowed), read by the one reader. Every value is finite, the
    times strictly increase, at least two rows; errors name the file and the line."""
    import numpy as np

    from ..granular.loads import tabulated
    from ..guard.reading import InputFileError, number, read_text

    text = read_text(path, "load table")
    times, forces, first = [], [], True
    import csv
    import io

    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        for row in reader:
            line = reader.line_num
            if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
                continue
            where = f"load table {path}, line {line}"
            header, first = first, False
            cells = [c.strip() for c in row]
            if header and len(cells) == 2 and cells[0].lower().startswith("time") and cells[1].lower().startswith("force"):
                continue  # the header, units allowed: time [s],force [N]
            if header and any(c[:1].isalpha() and c.lower() not in ("nan", "inf", "-inf", "infinity") for c in cells):
                raise InputFileError(f"{where}: the header must name the columns time,force, got {','.join(cells)!r}")
            if len(cells) != 2:
                raise InputFileError(f"{where}: expected two columns 'time,force', got {len(cells)} ({','.join(cells)!r})")
            t, f = number(cells[0], where, "time"), number(cells[1], where, "force")
            if times and t <= times[-1]:
                raise InputFileError(f"{where}: time {t!r} does not increase (previous {times[-1]!r})")
            times.append(t)
            forces.append(f)
    except csv.Error as e:
        raise InputFileError(f"load table {path}, line {reader.line_num}: not valid CSV ({e})") from None
    if len(times) < 2:
        raise InputFileError(f"load table {path}: need at least two rows of 'time,force'")
    return tabulated(np.array(times), np.array(forces))
