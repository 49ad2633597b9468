"""Preprocessing of MarineCadastre AIS files: read, clean, segment, cluster."""
