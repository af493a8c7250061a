"""REST api under ``/api/v1``: one router per resource, dependencies in ``deps``, errors in ``errors``."""
