"""aisdati: maritime AIS anomaly detection with domain-adaptive trajectory imitation (DATI)."""

__version__ = "0.1.0"
