"""Alembic migrations of the service database (run by ``storage.db.init_db``)."""
