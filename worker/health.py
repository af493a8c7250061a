"""``python -m worker.health [--name NAME]``: exit 0 if a worker of this host is alive, 1 otherwise.

Alive means: a process holds the worker's name lock (it runs; see :mod:`worker.identity`) and touched
it within ``heartbeat_timeout_s`` (its reaper thread reached the database that recently). This is the
container healthcheck of a worker; the reasons for "unhealthy" go to stderr.
"""

from __future__ import annotations

import argparse
import sys
import time

from storage.settings import get_settings
from worker.identity import host_names, is_held, lock_path


def check(name: str | None = None) -> tuple[bool, str]:
    settings = get_settings()
    reasons = []
    for candidate in host_names(name):
        path = lock_path(settings.data_dir, candidate)
        if not path.is_file():
            if name is None and candidate != host_names()[0]:
                break  # host-2, host-3, ... are taken in order: none further
            reasons.append(f"{candidate}: no worker has run under this name")
            continue
        if not is_held(path):
            reasons.append(f"{candidate}: not running")
            continue
        age = time.time() - path.stat().st_mtime
        if age > settings.heartbeat_timeout_s:
            reasons.append(f"{candidate}: running, but no database round for {age:.0f} s")
            continue
        return True, f"{candidate}: alive ({age:.0f} s since its last database round)"
    return False, "; ".join(reasons) or "no worker found"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Exit 0 when this host's worker is alive.")
    ap.add_argument("--name", default=None, help="worker name (default: the host's workers)")
    ok, why = check(ap.parse_args(argv).name)
    print(why, file=sys.stderr if not ok else sys.stdout)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
