"""Tracks as ingest writes them: the data contracts (schema) and reading them back (store)."""
