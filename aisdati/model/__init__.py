"""DATI and the trajectory-imitation environment (no knowledge of AIS file formats)."""
