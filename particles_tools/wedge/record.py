"""The wedge folder: what was asked (``wedge.json``), what came of it (``index.csv``), the chosen
frame of each variant (``.thumbs/``), and per variant its whole config (``v003.toml``) and its
folder of frames (``v003/``).

``wedge.json`` and ``index.csv`` are rewritten whole (temporary name, then rename) after every
variant, so an interrupted wedge leaves a readable index; ``--resume`` skips the variants it marks
``ok`` whose frames are all there and whole, and runs the rest (a partial variant continues from
its last whole frame, as ``particles run --resume`` does).
"""
from __future__ import annotations

import csv
import io
import json
import os

from ..errors import OutputFailure, UserError

RECORD = "wedge.json"
INDEX = "index.csv"
SHEET = "contact_sheet.png"
THUMBS = ".thumbs"
#: index.csv columns after the variant id and its set values
RESULT_COLUMNS = ["status", "exit_code", "wall_s", "frames", "peak_particles", "dropped",
                  "resumed_at", "worker", "message"]


def variant_dir(out: str, variant_id: str) -> str:
    return os.path.join(out, variant_id)


def thumb_path(out: str, variant_id: str) -> str:
    return os.path.join(out, THUMBS, f"{variant_id}.png")


def write_atomic(path: str, data: bytes) -> None:
    tmp = os.path.join(os.path.dirname(path), f".{os.path.basename(path)}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)


def _differences(old: dict, new: dict):
    return [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]


def check_folder(out: str, wedge, resume: bool) -> dict:
    """Check ``out`` can take ``wedge``, writing nothing; returns {variant id: index row} of the
    variants a previous run finished (only with ``resume``). Refuses (exit 2) a folder holding
    anything without ``resume``, or a wedge made with other settings; exit 4 for a file."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise OutputFailure(f"--out: {out} exists and is not a directory")
    held = sorted(os.listdir(out)) if os.path.isdir(out) else []
    if not held:
        return {}
    if not resume:
        raise UserError(f"--out: {out} already holds {len(held)} file(s) or folder(s); pass "
                        f"--resume to finish a wedge there, or choose another --out")
    try:
        with open(os.path.join(out, RECORD)) as fh:
            old = json.load(fh)["wedge"]
    except (OSError, ValueError, KeyError, TypeError):
        raise UserError(f"--resume: {out} holds no readable {RECORD}; it is not a wedge folder"
                        ) from None
    diff = _differences(old, wedge.record())
    if diff:
        raise UserError(f"--resume: {out} was made with other settings ({', '.join(diff)}); "
                        f"choose another --out")
    return _finished(out, read_index(out))


def config_path(out: str, variant_id: str) -> str:
    return os.path.join(out, f"{variant_id}.toml")


def create_folder(out: str, wedge) -> None:
    """Create ``out`` (and its thumbnail folder), write the wedge's record and each variant's
    whole config (``v003.toml``: ``particles run v003.toml --out v003`` renders that variant);
    OSError if it cannot be written."""
    os.makedirs(os.path.join(out, THUMBS), exist_ok=True)
    write_record(out, wedge)
    for v in wedge.variants:
        write_atomic(config_path(out, v.id), v.config_text.encode("utf-8"))


def _finished(out: str, rows) -> dict:
    """Rows marked ok whose frames are all on disk and whole, and whose thumbnail is there."""
    from engine.render.resume import whole_frames

    done = {}
    for row in rows:
        vid = row.get("variant", "")
        try:
            frames = int(row.get("frames") or 0)
        except ValueError:
            continue
        if (row.get("status") == "ok" and frames > 0 and os.path.isfile(thumb_path(out, vid))
                and whole_frames(variant_dir(out, vid)) >= frames):
            done[vid] = row
    return done


def write_record(out: str, wedge, timing=None) -> None:
    doc = {"wedge": wedge.record(),
           "variants": [{"id": v.id, "label": v.label(wedge.keys)} for v in wedge.variants]}
    if timing:
        doc["timing"] = timing
    write_atomic(os.path.join(out, RECORD), json.dumps(doc, indent=1, sort_keys=True).encode())


def read_index(out: str):
    try:
        with open(os.path.join(out, INDEX), newline="") as fh:
            return list(csv.DictReader(fh))
    except (OSError, csv.Error, UnicodeDecodeError):
        return []


def index_row(wedge, variant, result=None) -> dict:
    """One index.csv row: the variant id, its set values as typed, then the result columns
    (``pending`` until a result arrives)."""
    row = {"variant": variant.id}
    row.update(zip(wedge.keys, variant.texts))
    if wedge.seeds is not None:
        row["seed"] = variant.seed
    res = result or {"status": "pending"}
    row.update({c: res.get(c, "") for c in RESULT_COLUMNS})
    return row


def write_index(out: str, wedge, rows) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["variant"] + wedge.columns + RESULT_COLUMNS,
                       lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_atomic(os.path.join(out, INDEX), buf.getvalue().encode())


def save_thumb(out: str, variant_id: str, png: bytes) -> None:
    write_atomic(thumb_path(out, variant_id), png)
