"""Result files (result.json, diagnosis.json): read one, write one whole or not at all.

The documents themselves are built where their content is known
(:func:`motorid.identify.results.result_document`,
:func:`motorid.discrepancy.select.diagnosis_document`); this module only moves
them to and from disk.
"""

from __future__ import annotations

import json
from pathlib import Path

from motorid._atomic import write_bytes_atomic
from motorid.errors import InputError

RESULT_FILE = "result.json"
DIAGNOSIS_FILE = "diagnosis.json"


def read_json(path, what: str) -> dict:
    """The JSON document at ``path``; :class:`InputError` naming the file (and ``what`` it should be) if not."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None


def read_diagnosis_beside(folder) -> tuple[dict | None, str | None]:
    """The diagnosis.json of a result folder, where diagnose wrote one → (its document, None);
    (None, None) where there is none; (None, the one-line reason) where it does not read."""
    path = Path(folder) / DIAGNOSIS_FILE
    if not path.exists():
        return None, None
    try:
        return read_json(path, DIAGNOSIS_FILE), None
    except InputError as exc:
        return None, str(exc)


def write_json(doc: dict, path) -> Path:
    """Write ``doc`` to ``path`` as indented JSON (no NaN), atomically: a temporary file, then a rename."""
    text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
    return write_bytes_atomic(path, text.encode())
