"""Tracks as ingest writes them: the data contracts (schema), reading them back (store), and
the physical check of where they report (ashore)."""
