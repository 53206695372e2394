"""Reading a capture's JSON file (``transforms.json``, a 3DGS ``cameras.json``) with one error style."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from ..errors import IngestError

__all__ = ["read_json_file"]


def read_json_file(path: str | os.PathLike, kind: str) -> Any:
    """The parsed JSON of ``path``; ``kind`` names the file in errors (``"transforms"``, ``"cameras"``).

    Raises :class:`IngestError` naming the file when it does not exist or is not readable JSON (nesting too deep
    for the parser included).
    """
    path = Path(path)
    if not path.is_file():
        raise IngestError(f"{kind} file {str(path)!r} does not exist")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise IngestError(f"{path}: not a readable JSON file ({exc})") from None
    except RecursionError:
        raise IngestError(f"{path}: not a readable JSON file (nested too deeply for the JSON parser); expected a "
                          f"{kind} file") from None
