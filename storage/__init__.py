"""Lowest layer of the service: settings, database models and repositories, artifact store, queue.

Imports none of ``backend``, ``worker``, ``webui``; builds nothing at import time.
"""
