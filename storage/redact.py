"""Server paths out of anything a client reads (error messages, job errors, ``log.txt``).

Paths below the data directory become relative to it (``sequences/ab12/rgb.txt``: still useful to the
user, who knows the sequence); any other absolute path (the import root, a traceback's source files)
keeps only its last component (``…/tasks.py``).
"""

from __future__ import annotations

import re
from pathlib import Path

_ABSOLUTE = re.compile(r"(?<![\w.:/~-])(/[^\s/\"'(),:;<>\[\]{}]+){2,}")


def redact_paths(text: str, data_dir: Path | None = None) -> str:
    """``text`` without absolute server paths (see the module docstring)."""
    if data_dir is not None:
        for root in {str(data_dir.resolve()), str(data_dir.absolute())}:
            if root != "/":
                text = text.replace(root + "/", "").replace(root, ".")
    return _ABSOLUTE.sub(lambda m: "…/" + m.group(0).rsplit("/", 1)[-1], text)
