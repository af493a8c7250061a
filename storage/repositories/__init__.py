"""All database queries. Each module holds plain functions taking a ``Session`` first.

Every write commits its own transaction (rolled back on error) and returns fresh objects; ``get`` and
the list functions always re-read rows, so a long-lived session never serves stale progress.
"""

from storage.repositories import batches, job_reaping, jobs, metrics, sequences

__all__ = ["batches", "job_reaping", "jobs", "metrics", "sequences"]
