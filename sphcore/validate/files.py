"""Reading back the files the validation commands wrote (`sphcore report`, `sphcore sweep`), as
untrusted input: a JSON, CSV or PNG that cannot be read, is truncated, binary or of the wrong
shape raises ResultsError, one line naming the file and what is wrong with it (the CLI prints
it and exits 1), never a traceback, and never a page or table drawn from nothing."""
import csv
import io
import json
from pathlib import Path

from sphcore.errors import ResultsError

JSON_NAMES = {dict: "an object", list: "an array"}
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"  # the last chunk of every PNG: its absence means a truncated file


def unreadable(path, why):
    error = ResultsError(f"{path}: {why}; make it again with the command that writes it, or move it away")
    error.why = why
    return error


def read_text(path):
    """The UTF-8 text of `path`; ResultsError if it cannot be read or is not text (a binary file)."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise unreadable(path, f"not a text file (byte {e.start} is not UTF-8)") from None
    except OSError as e:
        raise unreadable(path, f"cannot be read ({e.strerror or e})") from None


def read_json(path, kind=dict):
    """The JSON value in `path`, which must be a `kind` (dict or list; None: any)."""
    text = read_text(path)
    try:
        value = json.loads(text)
    except ValueError as e:  # truncated, not JSON
        raise unreadable(path, f"not valid JSON ({str(e)[:120]})") from None
    if kind is not None and not isinstance(value, kind):
        raise unreadable(path, f"holds {JSON_NAMES.get(type(value), 'a JSON ' + type(value).__name__)}, "
                               f"not {JSON_NAMES[kind]}")
    return value


def is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check(path, data, required=(), numbers=(), texts=(), dicts=(), lists=()):
    """`data` (a dict read from `path`): each key in `required` present; each key in `numbers`,
    `texts`, `dicts` and `lists` that is present (and not null) of that kind. Returns `data`."""
    missing = [k for k in required if k not in data]
    if missing:
        raise unreadable(path, f"has no {missing[0]!r}")
    for keys, test, name in ((numbers, is_number, "a number"), (texts, lambda v: isinstance(v, str), "text"),
                             (dicts, lambda v: isinstance(v, dict), "an object"),
                             (lists, lambda v: isinstance(v, list), "an array")):
        for k in keys:
            if data.get(k) is not None and not test(data[k]):
                raise unreadable(path, f"{k!r} is {str(data[k])[:40]!r}, not {name}")
    return data


def number(text):
    """A CSV cell: int where whole and written so, float, None where empty, else the text."""
    if text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        return text
    return int(value) if value.is_integer() and "." not in text and "e" not in text.lower() else value


def read_csv(path, numbers=(), min_rows=0):
    """Rows of a CSV as dicts (cells through `number`), every row as long as the header, at least
    `min_rows` of them; each column in `numbers` ("all": every column) present and a number in
    every row (NaN allowed: a measurement that found nothing)."""
    text = read_text(path)
    try:
        reader = csv.reader(io.StringIO(text, newline=""))
        header = next(reader, None)
        lines = list(reader)
    except csv.Error as e:  # a field past the csv module's size limit
        raise unreadable(path, f"not a CSV table ({e})") from None
    if header is None:
        raise unreadable(path, "empty (no header line)")
    numbers = header if numbers == "all" else numbers
    missing = [c for c in numbers if c not in header]
    if missing:
        raise unreadable(path, f"has no column {missing[0]!r}")
    rows = []
    for line_number, cells in enumerate(lines, 2):
        if not cells:
            continue
        if len(cells) != len(header):
            raise unreadable(path, f"line {line_number} has {len(cells)} cells, the header {len(header)} "
                                   "(truncated?)")
        row = {k: number(v) for k, v in zip(header, cells)}
        bad = [c for c in numbers if not is_number(row[c])]
        if bad:
            raise unreadable(path, f"line {line_number}: {bad[0]} = {cells[header.index(bad[0])][:40]!r} is not "
                                   "a number")
        rows.append(row)
    if len(rows) < min_rows:
        raise unreadable(path, f"has {len(rows)} rows of data, fewer than {min_rows}")
    return rows


def check_png(path):
    """`path`, checked to be a whole PNG (its signature first and its end chunk last): a damaged
    picture would be copied into a page that shows nothing."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - 8))
            tail = f.read()
    except OSError as e:
        raise unreadable(path, f"cannot be read ({e.strerror or e})") from None
    if head != PNG_SIGNATURE:
        raise unreadable(path, "not a PNG image")
    if tail != PNG_END:
        raise unreadable(path, f"a truncated PNG image ({size} bytes, no end chunk)")
    return Path(path)
